"""The language suite's data: its sentences, its fixed scenes and the (sentence, scene) cases.

The suite file (``bench/data/language_suite.json``) holds sentences written by hand as people type
them, each with a hand-written query (:mod:`scenes.language.query`), the ``scenes.synth`` arguments
of its fixed synthetic scenes and a fingerprint of those scenes (per scene: the actor count and a
hash of the rounded boxes and velocities), so that a generator change that alters the scenes
stops the suite with a clear error instead of silently changing it
(``python -m bench.language_suite --write-fingerprint`` records the new scenes on purpose).

A **case** is a sentence in a scene where :func:`scenes.language.resolve.resolve` gives an answer
(not refused): every scene for out-of-class sentences, the scenes where nothing matches for
unsatisfiable ones, scenes with at least one referent for the single-referent and rewording
families, any answer (the empty set included) for negation, exclusion and counting. At most
:data:`MAX_SCENES_PER_SENTENCE` scenes per sentence are kept, drawn by a generator seeded from the
sentence id, so the suite stays a few thousand cases. The ``command`` family (driving instructions
typed in Talk2Car's style, none of them the generator's command templates) pairs each sentence
with its plain description (``command_description``, id ``<id>-desc``, the same query), chosen on
the same scenes (:func:`selection_key`), so that the two rows measure the cost of the wrapping.

The actors are the synthetic root's own (its sidecar, ``meta/``), less those it lists as seen by
neither sensor (``extra.unsensed_actor_ids``): a person looking at the scene could not see them.
"""

from __future__ import annotations

import hashlib
import json
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes.geometry.actors import Actor
from scenes.language.query import Query, QueryError, parse_query
from scenes.language.resolve import resolve
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.utils.durable import atomic_write_text
from scenes.utils.textfile import read_json_file

SUITE_FILE = Path(__file__).resolve().parents[1] / "data" / "language_suite.json"
DEFAULT_SCENES = Path("runs/language-suite-scenes")
FAMILIES = (
    "out_of_class",
    "unsatisfiable",
    "negation",
    "ordinal",
    "exclusion",
    "relation",
    "counting",
    "rewording",
    "command",
    "command_description",
)
COMMAND, COMMAND_DESCRIPTION = "command", "command_description"
DESCRIPTION_SUFFIX = "-desc"
"""A ``command`` sentence ``cmd-07`` ("hold back until the person who's crossing has gone") has its
plain description ``cmd-07-desc`` ("the person who's crossing", family ``command_description``)
with the same query; both are kept on the same scenes, so the two families' figures are the cost
of wrapping a description in a driving command (issue 40 item 4)."""
EMPTY_FAMILIES = ("out_of_class", "unsatisfiable")
"""Families whose correct answer is no box."""
SINGLE_FAMILIES = ("ordinal", "relation", COMMAND, COMMAND_DESCRIPTION)
"""Families scored by top-1 (one referent, or the top box must be one of a few)."""
SET_FAMILIES = ("negation", "exclusion", "counting")
"""Families scored as sets (set F1, exact set)."""
MAX_SCENES_PER_SENTENCE = 10
SPLIT = "test"


class SuiteError(ValueError):
    """The suite file or its scenes are not what they should be; the message says which and how."""


@dataclass(frozen=True)
class Sentence:
    """One entry of the suite file."""

    id: str
    family: str
    text: str
    query: Query


@dataclass(frozen=True)
class Suite:
    """The suite file: sentences, the scenes' ``synth_args`` and their ``fingerprint``."""

    sentences: tuple[Sentence, ...]
    synth_args: tuple[str, ...]
    fingerprint: tuple[dict, ...]
    source: str = "<suite>"


@dataclass(frozen=True)
class Case:
    """A sentence in one scene with its referents (actor ids, ascending)."""

    sentence: Sentence
    sample_id: str
    referents: tuple[int, ...]


def parse_suite(data: object, source: str) -> Suite:
    """A :class:`Suite` from the file's JSON; errors name ``source`` and the entry."""
    if not isinstance(data, dict) or not isinstance(data.get("sentences"), list):
        raise SuiteError(f"{source}: expected an object with a 'sentences' list")
    sentences, seen = [], set()
    for i, e in enumerate(data["sentences"]):
        at = f"{source}: sentences[{i}]"
        if not isinstance(e, dict) or set(e) != {"id", "family", "text", "query"}:
            raise SuiteError(f"{at}: an entry has exactly id, family, text and query")
        if not isinstance(e["id"], str) or e["id"] in seen:
            raise SuiteError(f"{at}: id {e['id']!r} is not a new string")
        seen.add(e["id"])
        if e["family"] not in FAMILIES:
            raise SuiteError(f"{at} ({e['id']}): unknown family {e['family']!r}")
        if not isinstance(e["text"], str) or not e["text"].strip():
            raise SuiteError(f"{at} ({e['id']}): empty text")
        try:
            query = parse_query(e["query"], f"{e['id']}.query")
        except QueryError as exc:
            raise SuiteError(f"{source}: {exc}") from exc
        if (e["family"] == "out_of_class") != (query.out_of_class is not None):
            raise SuiteError(f"{at} ({e['id']}): out_of_class queries belong to that family only")
        sentences.append(Sentence(e["id"], e["family"], e["text"], query))
    scenes = data.get("scenes", {})
    args = scenes.get("synth_args") if isinstance(scenes, dict) else None
    if not isinstance(args, list) or not all(isinstance(a, str) for a in args):
        raise SuiteError(f"{source}: scenes.synth_args must be a list of strings")
    _check_command_pairs(sentences, source)
    fingerprint = scenes.get("fingerprint", [])
    if not isinstance(fingerprint, list):
        raise SuiteError(f"{source}: scenes.fingerprint must be a list")
    return Suite(tuple(sentences), tuple(args), tuple(fingerprint), source)


def _check_command_pairs(sentences: Sequence[Sentence], source: str) -> None:
    """Every command has its description (``<id>-desc``, same query) and every description its
    command."""
    by_id = {s.id: s for s in sentences}
    for s in sentences:
        if s.family == COMMAND:
            twin = by_id.get(s.id + DESCRIPTION_SUFFIX)
            if twin is None or twin.family != COMMAND_DESCRIPTION or twin.query != s.query:
                raise SuiteError(
                    f"{source}: command {s.id} needs a {COMMAND_DESCRIPTION} "
                    f"{s.id}{DESCRIPTION_SUFFIX} with the same query"
                )
        elif s.family == COMMAND_DESCRIPTION:
            twin = by_id.get(s.id.removesuffix(DESCRIPTION_SUFFIX))
            if not s.id.endswith(DESCRIPTION_SUFFIX) or twin is None or twin.family != COMMAND:
                raise SuiteError(
                    f"{source}: {COMMAND_DESCRIPTION} {s.id} is not <command id>{DESCRIPTION_SUFFIX}"
                )


def selection_key(sentence: Sentence) -> str:
    """What seeds the choice of a sentence's scenes: its id, a description's command's id (so
    both are scored on the same cases)."""
    if sentence.family == COMMAND_DESCRIPTION:
        return sentence.id.removesuffix(DESCRIPTION_SUFFIX)
    return sentence.id


def load_suite(path: str | Path = SUITE_FILE) -> Suite:
    """Read and check the suite file."""
    data = read_json_file(path, "language suite", SuiteError)
    return parse_suite(data, str(path))


def write_fingerprint(path: str | Path, fingerprint: Sequence[dict]) -> None:
    """Replace the suite file's ``scenes.fingerprint`` (atomic), keeping everything else."""
    data = read_json_file(path, "language suite", SuiteError)
    if not isinstance(data, dict):
        raise SuiteError(f"{path}: expected an object with a 'sentences' list")
    data.setdefault("scenes", {})["fingerprint"] = list(fingerprint)
    atomic_write_text(path, dump_suite(data))


def dump_suite(data: dict) -> str:
    """The suite file's text: one sentence and one scene per line."""
    lines = ["{", f' "about": {json.dumps(data.get("about", ""))},', ' "scenes": {']
    scenes = data.get("scenes", {})
    lines.append(f'  "synth_args": {json.dumps(scenes.get("synth_args", []))},')
    prints = [json.dumps(f, sort_keys=True) for f in scenes.get("fingerprint", [])]
    if prints:
        lines.append('  "fingerprint": [\n   ' + ",\n   ".join(prints) + "\n  ]")
    else:
        lines.append('  "fingerprint": []')
    lines.append(" },")
    rows = [json.dumps(e, ensure_ascii=False) for e in data["sentences"]]
    lines.append(' "sentences": [\n  ' + ",\n  ".join(rows) + "\n ]")
    lines.append("}")
    return "\n".join(lines) + "\n"


def scene_actors(root: Talk2RadarRoot, sample_id: str) -> tuple[Actor, ...]:
    """The actors of a scene a person could see: the sidecar's, less the unsensed ones."""
    meta = root.load_meta(sample_id)
    if meta is None:
        raise SuiteError(f"{root.path}: sample {sample_id} has no sidecar (meta/)")
    unsensed = set(meta.extra.get("unsensed_actor_ids", ()))
    return tuple(a for a in meta.actors if a.actor_id not in unsensed)


def fingerprint(root: Talk2RadarRoot) -> list[dict]:
    """Per scene of the test split: id, actor count, and a hash of rounded boxes and velocities."""
    out = []
    for sid in root.ids(SPLIT):
        actors = scene_actors(root, sid)
        rows = [
            [a.actor_id, a.cls, *np.round(a.box, 2).tolist(), *np.round(a.velocity, 2).tolist()]
            for a in actors
        ]
        digest = hashlib.sha256(json.dumps(rows).encode()).hexdigest()[:16]
        out.append({"id": sid, "actors": len(actors), "hash": digest})
    return out


def check_fingerprint(suite: Suite, root: Talk2RadarRoot) -> None:
    """Raise :class:`SuiteError` when the scenes are not the ones the suite was made on."""
    got = fingerprint(root)
    want = list(suite.fingerprint)
    if got == want:
        return
    if len(got) != len(want):
        detail = f"{len(got)} scenes, the suite expects {len(want)}"
    else:
        first = next(g for g, w in zip(got, want, strict=True) if g != w)
        detail = f"scene {first['id']} differs ({first} against the suite's)"
    raise SuiteError(
        f"{root.path}: not the suite's scenes ({suite.source}): {detail}. If the generator "
        f"changed on purpose, regenerate the scenes and record them with "
        f"`python -m bench.language_suite --write-fingerprint`"
    )


def ensure_scenes(suite: Suite, folder: str | Path) -> Talk2RadarRoot:
    """The suite's scenes under ``folder``, generated first when missing (``scenes.synth``)."""
    folder = Path(folder)
    if not (folder / "synth_manifest.jsonl").exists():
        from scenes.synth.generate import main as synth_main

        code = synth_main(["--out", str(folder), *suite.synth_args])
        if code != 0:
            raise SuiteError(f"{folder}: scenes.synth failed (exit {code})")
    return Talk2RadarRoot(folder)


def _keeps(sentence: Sentence, referents: tuple[int, ...]) -> bool:
    if sentence.family in EMPTY_FAMILIES:
        return not referents
    if sentence.family in SET_FAMILIES:
        return True
    return bool(referents)


def build_cases(
    suite: Suite, root: Talk2RadarRoot, max_scenes: int = MAX_SCENES_PER_SENTENCE
) -> list[Case]:
    """Every sentence on the scenes where it has a usable answer (module docstring), at most
    ``max_scenes`` per sentence, in suite then scene order."""
    ids = root.ids(SPLIT)
    actors = {sid: scene_actors(root, sid) for sid in ids}
    cases: list[Case] = []
    for sentence in suite.sentences:
        usable = []
        for sid in ids:
            res = resolve(sentence.query, actors[sid])
            if res.refused is None and _keeps(sentence, res.ids):
                usable.append(Case(sentence, sid, res.ids))
        if len(usable) > max_scenes:
            rng = np.random.default_rng(zlib.crc32(selection_key(sentence).encode()))
            keep = sorted(rng.choice(len(usable), size=max_scenes, replace=False))
            usable = [usable[i] for i in keep]
        cases.extend(usable)
    return cases
