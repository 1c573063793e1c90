"""Which saved pairs a reviewer approved, read from a root's annotation manifest.

The annotation store (:mod:`annotate`) logs every save, edit and deletion of a pair in
``<root>/annotations/manifest.jsonl`` (:func:`scenes.talk2radar.layout.manifest_file`, format in
docs/ANNOTATION.md), and a reviewer's verdict on a version of a pair as a ``review`` line
(``verdict``: ``approved``, ``rejected`` or ``fixed``: the reviewer edited the pair and approves
the version the edit wrote). A pair counts as approved when the latest review of its *current*
version (the version of its last create / edit line) approves it; an edit after an approval makes
a new, unreviewed version.

:func:`approved_ids` is what training and evaluation restrict to (``--approved-only``); it lives
here, in the data domain, so that ``model`` can read it without the annotation package. It reads
the manifest's lines leniently (a torn or unreadable line is skipped, as the store's reader does)
and never writes.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from scenes.talk2radar.layout import (
    LIDAR_FOLDER,
    format_id,
    manifest_file,
    parse_split_list,
    split_file,
)
from scenes.utils.durable import read_json_lines
from scenes.utils.errors import RootError
from scenes.utils.textfile import read_text_file

REVIEW = "review"
"""The manifest ``action`` of a review line."""
VERDICTS = ("approved", "rejected", "fixed")
"""A review's verdicts."""
APPROVING = frozenset({"approved", "fixed"})
"""The verdicts that approve the version reviewed."""


@dataclass(frozen=True)
class PairReview:
    """The latest review of a pair's current version.

    Attributes:
        sample_id: The pair's 5-digit id.
        version: The version reviewed (the pair's current version).
        verdict: One of :data:`VERDICTS`.
        reviewer: Who reviewed it.
        time: ISO 8601 time of the review.
        note: The reviewer's note ("" when none).
    """

    sample_id: str
    version: int
    verdict: str
    reviewer: str
    time: str
    note: str = ""

    @property
    def approved(self) -> bool:
        return self.verdict in APPROVING


@dataclass(frozen=True)
class PairState:
    """A pair's current version and the latest review of it (None: not reviewed)."""

    version: int
    deleted: bool
    review: PairReview | None


def _line(value: object) -> Mapping[str, object]:
    if not isinstance(value, dict) or "action" not in value or "sample_id" not in value:
        raise ValueError("not a manifest line")
    int(value["version"])
    return value


def pair_states(lines: Iterable[Mapping[str, object]]) -> dict[str, PairState]:
    """Each pair's :class:`PairState` from manifest lines (dicts, oldest first)."""
    out: dict[str, PairState] = {}
    for line in lines:
        sid = format_id(str(line["sample_id"]))
        version = int(line["version"])  # type: ignore[arg-type]
        action = str(line["action"])
        state = out.get(sid)
        if action != REVIEW:
            out[sid] = PairState(version, action == "delete", None)
        elif state is not None and version == state.version and line.get("verdict") in VERDICTS:
            review = PairReview(
                sid,
                version,
                str(line["verdict"]),
                str(line.get("annotator", "")),
                str(line.get("time", "")),
                str(line.get("note") or ""),
            )
            out[sid] = PairState(state.version, state.deleted, review)
    return out


def read_pair_states(root: str | Path) -> dict[str, PairState]:
    """:func:`pair_states` of a root's manifest (empty when it has none)."""
    log = read_json_lines(manifest_file(Path(root)), _line)
    return pair_states(entry for _, entry in log.entries)


def approved_ids(root: str | Path, split: str) -> tuple[str, ...]:
    """The sample ids of ``split`` (in list order) whose current version a reviewer approved
    (see the module docstring); samples the manifest never recorded are not approved.

    Raises:
        RootError: the root has no list of ``split``, or it is malformed (the line named).
    """
    path = split_file(Path(root) / LIDAR_FOLDER, split)
    listed = parse_split_list(read_text_file(path, f"list of split {split!r}", RootError), path)
    states = read_pair_states(root)
    out = []
    for sid in listed:
        state = states.get(sid)
        review = state.review if state is not None and not state.deleted else None
        if review is not None and review.approved:
            out.append(sid)
    return tuple(out)
