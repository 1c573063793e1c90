"""The ``--freeze-scene`` cache kept on disk: a scene encoded once is reused by every later run.

A ``--freeze-scene`` run encodes each training scene with the frozen scene encoder and detector
and banks its prompts' frozen MiniLM features (:mod:`model.training.referent_cache`). That costs
the same in every run over the same root with the same detector, so both are kept in a
content-addressed store and a later run (another step budget, learning rate, batch, seed of the
steps, ``--init`` or ``--init-detector``, or a ``--resume``) reads them back instead:

- **Scenes** (:class:`SceneStore`): ``<cache>/scenes/<model>/<xx>/<key>.pt``, one file per
  cached scene (its view and, when cached, its labelled view). ``<model>`` is the digest of
  everything the candidates depend on (:func:`model_digest`: the model's config and every tensor
  outside the referent stage, which learns and which the candidates never read: a test checks
  both); ``<key>`` that of the scene as loaded (every field of its
  :class:`scenes.datasets.frames.FrameItem`: points, actors, given prompts, ...) and whether its
  labelled view is kept (:func:`scene_key`). A changed file, another loader or another detector
  give another key: a stale entry is never read, only left unused. The prompts are not kept:
  each run draws them again (cheaply, from its own settings), so runs of other prompt settings
  share the scenes.
- **Prompt features** (:class:`TextStore`): ``<cache>/texts/<encoder>/``, the texts of each
  chunk encoded together in one file, listed in ``index.jsonl``; ``<encoder>`` names the text
  encoder, its package version and ``max_tokens``. A text read back equals the one first
  encoded; one encoded again in another batch equals it to float rounding
  (:func:`model.nets.text.encode_minilm_batched`).

Resumable: every scene is written as soon as it is encoded, and every chunk of prompts, so an
interrupted caching pass resumes where it stopped. Files are written atomically (:func:`scenes.utils.durable.atomic_file`)
and read with ``torch.load(weights_only=True)`` (tensors, lists, strings, numbers only: a cache
file cannot run code); an unreadable file is a miss and is written again. A store that cannot be
written (a full disk, no permission) says so once and the run goes on without it: the cache only
saves time, it never decides a result (a run from the store trains to the same weights as one
without it; a test checks this).

Where: ``--cache DIR`` (default :func:`default_cache_dir`: ``$TALK2PC_CACHE``, else
``$XDG_CACHE_HOME/talk2pc``, else ``~/.cache/talk2pc``); ``--cache none`` keeps nothing. A folder
that is, lies inside or contains a training root or its command folder is refused with one line
(a release's files are never written). Deleting the folder is always safe.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from importlib import metadata
from pathlib import Path

import torch

from scenes.datasets.frames import FrameItem
from scenes.utils.durable import append_json_line, atomic_file, read_json_lines
from scenes.utils.owned import check_apart

STORE_VERSION = 2
"""Bumped whenever what a cached scene or text holds, or how it is computed, changes."""

NO_CACHE = "none"
"""``--cache none``: keep nothing on disk."""

TextEntry = tuple[torch.Tensor, torch.Tensor, bool]
"""A banked prompt's frozen features (:class:`model.training.referent_cache.TextBank`)."""


def default_cache_dir() -> Path:
    """``$TALK2PC_CACHE``, else ``$XDG_CACHE_HOME/talk2pc``, else ``~/.cache/talk2pc``."""
    if os.environ.get("TALK2PC_CACHE"):
        return Path(os.environ["TALK2PC_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "talk2pc"


def _digest(*parts: bytes | str) -> str:
    h = hashlib.sha256()
    for part in parts:
        data = part.encode() if isinstance(part, str) else part
        h.update(len(data).to_bytes(8, "little"))
        h.update(data)
    return h.hexdigest()


def model_digest(model: torch.nn.Module) -> str:
    """Digest of what a scene's cached candidates depend on: ``model.cfg`` (the referent stage's
    dropout left out: it never acts while encoding) and every tensor of the state but the
    grounding head's (the referent stage, which a ``--freeze-scene`` run trains, and which
    :meth:`model.grounding.referent.ReferentGrounding.encode_views` does not read)."""
    cfg = model.cfg  # type: ignore[attr-defined]
    cfg = replace(cfg, referent=replace(cfg.referent, dropout=0.0))
    parts: list[bytes | str] = [f"store {STORE_VERSION}", repr(cfg)]
    grounding = model.grounding  # type: ignore[attr-defined]
    learnt = {id(t) for t in (*grounding.parameters(), *grounding.buffers())}
    for name, tensor in sorted(model.state_dict(keep_vars=True).items()):
        if id(tensor) in learnt:  # the referent stage, under whichever name the model shows it
            continue
        t = tensor.detach().cpu().contiguous().reshape(-1)
        parts += [
            name,
            str(t.dtype),
            repr(tuple(tensor.shape)),
            t.view(torch.uint8).numpy().tobytes(),
        ]
    return _digest(*parts)


def scene_key(item: FrameItem, labelled: bool) -> str:
    """The store key of a scene loaded as ``item`` (as the model sees it), cached with its
    labelled view or not: every field of the item, pickled."""
    return _digest(f"labelled {labelled}", pickle.dumps(item, protocol=5))


def _save(path: Path, value: object) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as handle:
        torch.save(value, handle)


def _load(path: Path) -> object | None:
    """The file's content, or None where it is missing or unreadable (a miss)."""
    if not path.is_file():
        return None
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception:  # a torn or foreign file is a miss, written again
        return None


@dataclass
class CacheWrites:
    """Whether a run's stores can still be written: the first failed write says so (one line)
    and every later one is skipped."""

    ok: bool = True

    def attempt(self, path: Path, value: object) -> None:
        """Write ``value`` to ``path`` (:func:`_save`) unless an earlier write failed."""
        if not self.ok:
            return
        try:
            _save(path, value)
        except OSError as exc:
            self.fail(path, exc)

    def fail(self, path: Path, exc: OSError) -> None:
        self.ok = False
        print(
            f"--cache: cannot write {path} ({exc.strerror or exc}); the run goes on without "
            "keeping its cache",
            file=sys.stderr,
        )


@dataclass
class SceneStore:
    """Cached scenes of one model (:func:`model_digest`) under ``<cache>/scenes/``.

    Attributes:
        folder: ``<cache>/scenes/<model digest>``.
        hits: Scenes read back this run (the progress bar shows them).
    """

    folder: Path
    hits: int = 0
    writes: CacheWrites = field(default_factory=CacheWrites)

    @classmethod
    def open(
        cls, cache: Path, model: torch.nn.Module, writes: CacheWrites | None = None
    ) -> SceneStore:
        """The store of ``model``'s scenes in the cache folder ``cache``."""
        return cls(
            Path(cache) / "scenes" / model_digest(model)[:32], writes=writes or CacheWrites()
        )

    def _path(self, key: str) -> Path:
        return self.folder / key[:2] / f"{key}.pt"

    def load(self, key: str) -> dict | None:
        """The state stored under ``key``
        (:meth:`model.training.referent_cache.EncodedScene.state`), or None."""
        d = _load(self._path(key))
        if not isinstance(d, dict) or d.get("version") != STORE_VERSION:
            return None
        self.hits += 1
        return d["scene"]

    def save(self, key: str, state: dict) -> None:
        """Keep a scene's ``state`` under ``key`` (atomically; a failed write is said once)."""
        self.writes.attempt(self._path(key), {"version": STORE_VERSION, "scene": state})


def text_encoder_name(max_tokens: int) -> str:
    """The text store's folder name: the MiniLM package, its version and ``max_tokens``."""
    from model.nets.text import MINILM_PACKAGE

    try:
        version = metadata.version(MINILM_PACKAGE)
    except metadata.PackageNotFoundError:
        version = "unknown"
    return f"minilm-{version}-t{max_tokens}-v{STORE_VERSION}"


def _text_digest(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()[:32]


@dataclass
class TextStore:
    """Banked prompt features under ``<cache>/texts/<encoder>/``: one file per batch of texts
    saved together (``<digest>.pt``, ``{text: (tokens, numbers, truncated)}``) and an index,
    ``index.jsonl``, of which texts each holds (one line per file, appended after the file is
    written: a file whose line is missing or torn is only unused).

    Attributes:
        folder: ``<cache>/texts/<encoder>``.
    """

    folder: Path
    writes: CacheWrites = field(default_factory=CacheWrites)

    @classmethod
    def open(cls, cache: Path, max_tokens: int, writes: CacheWrites | None = None) -> TextStore:
        """The store of MiniLM features at ``max_tokens`` in the cache folder ``cache``."""
        return cls(
            Path(cache) / "texts" / text_encoder_name(max_tokens), writes=writes or CacheWrites()
        )

    def _index(self) -> dict[str, str]:
        """Text digest -> the file holding it."""
        where: dict[str, str] = {}
        for _, entry in read_json_lines(self.folder / "index.jsonl").entries:
            if isinstance(entry, dict) and isinstance(entry.get("texts"), list):
                where.update(dict.fromkeys(map(str, entry["texts"]), str(entry.get("file"))))
        return where

    def load(self, texts: Iterable[str]) -> dict[str, TextEntry]:
        """The stored features of those of ``texts`` the store holds."""
        where = self._index()
        files: dict[str, list[str]] = {}
        for text in texts:
            name = where.get(_text_digest(text))
            if name is not None:
                files.setdefault(name, []).append(text)
        found: dict[str, TextEntry] = {}
        for name, wanted in files.items():
            held = _load(self.folder / Path(name).name)
            if not isinstance(held, dict):
                continue
            for text in wanted:
                entry = held.get(text)
                if isinstance(entry, list | tuple) and len(entry) == 3:
                    found[text] = (entry[0], entry[1], bool(entry[2]))
        return found

    def save(self, entries: dict[str, TextEntry]) -> None:
        """Keep ``entries`` as one file, then list it in the index."""
        if not entries or not self.writes.ok:
            return
        digests = [_text_digest(t) for t in entries]
        name = f"{_digest(*digests)[:32]}.pt"
        self.writes.attempt(self.folder / name, {t: list(e) for t, e in entries.items()})
        if self.writes.ok:
            try:
                append_json_line(self.folder / "index.jsonl", {"file": name, "texts": digests})
            except OSError as exc:
                self.writes.fail(self.folder / "index.jsonl", exc)


@dataclass(frozen=True)
class FrozenStore:
    """The scene and text stores of one ``--freeze-scene`` run."""

    scenes: SceneStore
    texts: TextStore

    @classmethod
    def open(cls, cache: str | Path, model: torch.nn.Module, max_tokens: int) -> FrozenStore:
        """Both stores in the cache folder ``cache`` (a failed write stops both, said once)."""
        writes = CacheWrites()
        return cls(
            SceneStore.open(Path(cache), model, writes),
            TextStore.open(Path(cache), max_tokens, writes),
        )


def open_store(
    cache: str, model: torch.nn.Module, max_tokens: int, apart: Mapping[str, str | Path]
) -> FrozenStore | None:
    """The run's store in ``cache`` (a folder, ``""`` for :func:`default_cache_dir`), or None
    for ``none``.

    Raises:
        scenes.utils.owned.FolderError: the folder is, lies inside or contains one of ``apart``
            (what each is -> its path: the training roots, whose files are the user's; one line,
            nothing written).
    """
    if cache == NO_CACHE:
        return None
    folder = Path(cache) if cache else default_cache_dir()
    check_apart(folder, apart)
    return FrozenStore.open(folder, model, max_tokens)


__all__ = [
    "NO_CACHE",
    "STORE_VERSION",
    "CacheWrites",
    "FrozenStore",
    "SceneStore",
    "TextStore",
    "default_cache_dir",
    "model_digest",
    "open_store",
    "scene_key",
    "text_encoder_name",
]
