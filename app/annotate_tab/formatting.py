"""What the Annotate tab writes into its dropdowns and markdown: pure functions of the draft, the
validation report, the evidence and the saved pairs. Every text that did not come from this code
(prompts, class names of a draft, annotator and split names, paths, messages) is escaped with
:func:`app.text.md_text`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from annotate import BoxEvidence, Draft, History, Motion, PairInfo, Severity, ValidationReport
from app.annotate_tab.view import box_tag
from app.text import md_text

NO_BOX = "(none)"
"""The *Box* dropdown's entry for "no box selected"."""

NO_PAIRS = "(no saved pairs)"
"""The *Pair* dropdown's only option while the root has no saved pair."""

NO_READY = "(none left)"
"""The *Object* dropdown's only option when every ready-made box is in the draft."""

RECENT_PAIRS = 8
"""Saved pairs shown in the table under the *Pair* dropdown (the most recent)."""

MOTION_TEXT = {
    Motion.APPROACHING: "approaching",
    Motion.RECEDING: "moving away",
    Motion.STATIC: "static",
    Motion.UNKNOWN: "no radar",
}
"""How the sign of a box's mean compensated radial velocity reads in the evidence table."""


def box_option(index: int, cls: str, box: Sequence[float]) -> str:
    """The *Box* dropdown entry of draft box ``index``: ``"#2 Car · 14.1 m"``."""
    return f"{box_tag(index, cls)} · {float(np.hypot(box[0], box[1])):.1f} m"


def option_index(option: str) -> int | None:
    """The 0-based box index of a :func:`box_option` entry (None for :data:`NO_BOX`)."""
    head = option.split(" ", 1)[0]
    if head.startswith("#") and head[1:].isdigit():
        return int(head[1:]) - 1
    return None


def ready_option(index: int, cls: str, box: Sequence[float]) -> str:
    """The *Object* dropdown entry of ready-made box ``index``: ``"3. Car · 15.1 m"``."""
    return f"{index + 1}. {cls} · {float(np.hypot(box[0], box[1])):.1f} m"


def option_ready_index(option: str) -> int | None:
    """The 0-based index of a :func:`ready_option` entry (None for :data:`NO_READY`)."""
    head = option.split(".", 1)[0]
    return int(head) - 1 if head.isdigit() else None


def placement_problem(messages: Sequence[str]) -> str:
    """Validation messages about one box (``"box 1 of 1 (Car): centre x = ..."``) as one
    sentence without the box's name."""
    return "; ".join(m.split(": ", 1)[1] if m.startswith("box 1 of 1") else m for m in messages)


def pair_option(pair: PairInfo) -> str:
    """The *Pair* dropdown entry of a saved pair: ``"00061 · 2 boxes · the cars ahead"``."""
    prompt = pair.prompt if len(pair.prompt) <= 48 else pair.prompt[:47] + "…"
    boxes = "1 box" if pair.num_boxes == 1 else f"{pair.num_boxes} boxes"
    return f"{pair.sample_id} · {boxes} · {prompt}"


def option_pair_id(option: str) -> str | None:
    """The pair id of a :func:`pair_option` entry: a sample id, or a Talk2Car command_token on a
    nuScenes root (None for :data:`NO_PAIRS`)."""
    head = option.split(" ", 1)[0]
    return head if head.isalnum() and head.isascii() else None


def evidence_markdown(
    draft: Draft, evidence: Sequence[BoxEvidence], selected_id: int | None
) -> str:
    """The evidence table: one row per box (the selected one in bold)."""
    if not draft.boxes:
        return "*No boxes yet: click the ground to place one.*"
    rows = [
        "| box | LiDAR | radar | mean v<sub>r</sub> | motion | dist |",
        "| --- | ---: | ---: | ---: | --- | ---: |",
    ]
    for i, (item, ev) in enumerate(zip(draft.boxes, evidence, strict=True)):
        v = "-" if ev.mean_radial_velocity is None else f"{ev.mean_radial_velocity:+.1f} m/s"
        cells = [
            md_text(box_tag(i, item.cls)),
            str(ev.lidar_points),
            str(ev.radar_points),
            v,
            MOTION_TEXT[ev.motion],
            f"{ev.distance:.1f} m",
        ]
        if item.box_id == selected_id:
            cells = [f"**{c}**" for c in cells]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def checks_markdown(report: ValidationReport, saving: bool = True) -> str:
    """What validation says about the draft, shown under *Save pair* (why it is disabled).

    Args:
        report: The draft's validation.
        saving: Whether pairs can be saved here at all (False: the status line says why, and a
            complete draft is not called ready to save).
    """
    lines = []
    if report.ok and not saving:
        lines.append("**The pair is complete**, but saving is unavailable (see the status above).")
    elif report.ok:
        lines.append("**Ready to save** (*Save pair*, or Enter in *Pair prompt*).")
    else:
        lines.append("**Save pair is disabled until:**")
        lines += [f"- {md_text(m)}" for m in report.messages()]
    warnings = report.messages(Severity.WARNING)
    if warnings:
        lines.append("**Warnings** (saving is allowed):")
        lines += [f"- {md_text(m)}" for m in warnings]
    return "\n".join(lines)


def pairs_markdown(pairs: Sequence[PairInfo], root: Path, limit: int = RECENT_PAIRS) -> str:
    """The table of the most recently saved pairs (every stored text escaped)."""
    if not pairs:
        return f"*No pair saved in {md_text(root)} yet.*"
    recent = sorted(pairs, key=lambda p: p.time, reverse=True)[:limit]
    rows = [
        f"{len(pairs)} saved pair(s) in {md_text(root)}; the latest:",
        "",
        "| id | v | split | boxes | prompt | by |",
        "| --- | ---: | --- | ---: | --- | --- |",
    ]
    for p in recent:
        rows.append(
            f"| {md_text(p.sample_id)} | {p.version} | {md_text(', '.join(p.splits))} | "
            f"{p.num_boxes} | {md_text(p.prompt)} | {md_text(p.annotator)} |"
        )
    return "\n".join(rows)


def status_markdown(
    draft: Draft,
    history: History,
    frame_name: str | None,
    visible: bool,
    pristine: bool,
    unavailable: str | None = None,
    saving_to: tuple[Path, str] | None = None,
    last_saved: str | None = None,
    note: str | None = None,
) -> str:
    """The line at the top of the tab: what is being edited, whether its frame is on screen,
    what *Undo* and *Redo* would do.

    Args:
        draft: The draft.
        history: Its undo / redo history.
        frame_name: The sample id of the draft's frame (None: no frame yet).
        visible: Whether the draft's frame is on screen.
        pristine: Whether the draft holds nothing worth keeping (:func:`annotate.is_pristine`).
        unavailable: Why saving is unavailable (None: the store is open).
        saving_to: The folder pairs are saved into when it is not the served root, and what it
            holds (:meth:`app.serving.served.ServedRoot.pairs_described`); None: the served
            root. Not shown while saving is unavailable (nothing is saved anywhere).
        last_saved: What the last save of this browser wrote (``"pair 00061 (version 1) in
            train"``), or None.
        note: One more line (how the referents were chosen), or None.
    """
    lines = []
    if unavailable is not None:
        lines.append(f"**Saving is unavailable:** {md_text(unavailable)}")
    if last_saved is not None:
        lines.append(f"**Saved {md_text(last_saved)}.**")
    if saving_to is not None and unavailable is None:
        folder, what = saving_to
        lines.append(f"Pairs are saved into {md_text(folder)} ({md_text(what)}).")
    if draft.sample_id is not None:
        lines.append(
            f"**Editing pair {md_text(draft.sample_id)}** (version {draft.base_version}); "
            f"*Save pair* writes version {draft.base_version + 1}."
        )
    elif frame_name is not None:
        lines.append(f"**New pair** on sample {md_text(frame_name)}.")
    if frame_name is not None and not visible and not pristine:
        lines.append(
            f"This draft belongs to sample {md_text(frame_name)}, not to the frame on screen: its "
            "boxes are hidden. *Back to the draft's frame* shows it; *New pair* starts over."
        )
    if note:
        lines.append(f"*{md_text(note)}*")
    undo = history.undo_label if history.can_undo else "-"
    redo = history.redo_label if history.can_redo else "-"
    lines.append(f"Undo: *{md_text(undo)}* · Redo: *{md_text(redo)}*")
    return "  \n".join(lines)
