"""Review mode in the Annotate tab: walk the saved pairs of a split and give each a verdict.

The *Review* folder: the split to review and *Only pairs not reviewed yet*; *Previous* / *Next*
open the split's pairs one by one (sample id order) into the draft, the way *Open pair* does, so
each pair's sentence is in *Pair prompt* and its boxes are drawn over the scene and into the
camera panel, on the frame it was annotated on. Then:

- **Approve** (key Y) records ``approved`` for the version shown;
- **Reject** (key X) records ``rejected``, with the *Note* if one is typed;
- **Save fix** (Shift+F): edit the pair first (boxes, classes, sentence), then this saves the
  edit (a new version) and records ``fixed`` for it: the reviewer approves their own fix.

Each verdict is a ``review`` line of the manifest with the reviewer's name (*Annotator*, under
*Save options*) (:func:`annotate.review.record_review`, docs/ANNOTATION.md), and the next pair
opens only once the verdict was recorded.

A verdict belongs to the pair the reviewer was shown: *Approve*, *Reject* and their keys Y / X
are made anew for each pair opened (:meth:`ReviewPanel.open`), bound to its id, version and the
latest review of it then (:class:`Shown`). A click or key press sent before the browser showed
the next pair reaches the old controls: it is the same request (a key of the tab, the pair
shown and the verdict), answered once (one line, one notification, one step), or, once the old
controls are gone, dropped by viser; it never lands on the next pair. A verdict on a version
someone else decided after it was shown here is refused with who decided what, and the pair is
shown again with that verdict. Approving with unsaved edits is refused (save them as a fix, or undo them); a pair changed
by someone else since it was opened is refused too (reopen it). Training and evaluation read the
approved pairs of a split with :func:`scenes.talk2radar.reviews.approved_ids`.
Family specifics: a pair's review state (:class:`scenes.talk2radar.reviews.PairState`, read from
the annotation manifest of a Talk2Radar pairs root) is that family's, imported from its room.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable
from dataclasses import dataclass

import viser

from annotate import ConflictError, PairInfo, StoreError
from annotate.review import latest_review, record_review, review_states
from app.annotate_tab.formatting import pair_option
from app.annotate_tab.keys import KEYS, Key
from app.annotate_tab.pairs import PairActions
from app.annotate_tab.panel import AnnotationPanel
from app.annotate_tab.widgets import SPLITS
from app.text import md_text
from scenes.talk2radar.reviews import PairState

PREVIOUS, NEXT = "Previous", "Next"
"""The step buttons."""


VERDICT_KEYS: dict[str, Key] = {k.action: k for k in KEYS if k.action in ("approve", "reject")}
"""The keys of the verdicts (registered per pair shown, :meth:`ReviewPanel.open`)."""


@dataclass(frozen=True)
class Shown:
    """The pair under review as it was shown: id, version, and the ``op`` of the latest review of
    that version then (None: not reviewed)."""

    sample_id: str
    version: int
    seen: str | None


@dataclass(frozen=True)
class ReviewWidgets:
    """The *Review* folder's handles (*Approve* and *Reject* as first built: the panel makes
    them anew for each pair shown)."""

    folder: viser.GuiFolderHandle
    split: viser.GuiDropdownHandle
    unreviewed: viser.GuiCheckboxHandle
    step: viser.GuiButtonGroupHandle
    status: viser.GuiMarkdownHandle
    approve: viser.GuiButtonHandle
    reject: viser.GuiButtonHandle
    fix: viser.GuiButtonHandle
    note: viser.GuiTextHandle


def build_review_widgets(gui: viser.GuiApi) -> ReviewWidgets:
    """The *Review* folder (collapsed)."""
    with gui.add_folder("Review", expand_by_default=False) as folder:
        split = gui.add_dropdown("Review split", SPLITS, initial_value=SPLITS[0])
        unreviewed = gui.add_checkbox(
            "Only not reviewed", False, hint="Skip the pairs whose current version has a verdict"
        )
        step = gui.add_button_group("Pairs", (PREVIOUS, NEXT))
        status = gui.add_markdown("*Next opens the split's first pair.*")
        approve = gui.add_button("Approve", color="green", icon=viser.Icon.CHECK, disabled=True)
        reject = gui.add_button("Reject", color="red", icon=viser.Icon.X, disabled=True)
        fix = gui.add_button(
            "Save fix",
            icon=viser.Icon.DEVICE_FLOPPY,
            disabled=True,
            hint="Save your edit of the pair (a new version) and approve it (Shift+F)",
        )
        note = gui.add_text("Note", "", hint="Why it was rejected (kept with the verdict)")
    return ReviewWidgets(folder, split, unreviewed, step, status, approve, reject, fix, note)


class ReviewPanel:
    """The *Review* folder of one browser's Annotate tab (see the module docstring).

    Args:
        panel: The tab's state and drawing.
        pairs: The tab's pair actions (opening and saving pairs).
    """

    def __init__(self, panel: AnnotationPanel, pairs: PairActions) -> None:
        self.panel = panel
        self.pairs = pairs
        self.w = build_review_widgets(panel.session.client.gui)
        self.current: Shown | None = None
        """The pair under review (None: none yet)."""
        self._token = uuid.uuid4().hex
        """This tab's part of its verdicts' request keys."""
        self._controls: list[viser.GuiButtonHandle | viser.CommandHandle] = [
            self.w.approve,
            self.w.reject,
        ]
        """The verdict buttons and keys bound to the pair shown."""
        self._wire()

    # ------------------------------------------------------------------ the queue

    def queue(self) -> list[tuple[PairInfo, PairState | None]]:
        """The pairs of the chosen split in id order (with *Only not reviewed*: those whose
        current version has no verdict), with their review state."""
        store = self.panel.store
        if store is None:
            return []
        states = review_states(store)
        split = self.w.split.value
        out = [(p, states.get(p.sample_id)) for p in store.pairs() if split in p.splits]
        if self.w.unreviewed.value:
            out = [(p, s) for p, s in out if s is None or s.review is None]
        return out

    def step(self, delta: int) -> None:
        """Open the next (``delta=1``) or previous pair of the queue."""
        queue = self.queue()
        if not queue:
            self.current = None
            self._show("*No pair to review in this split.*")
            return
        ids = [p.sample_id for p, _ in queue]
        sid = self.current.sample_id if self.current is not None else None
        if sid in ids:
            index = ids.index(sid) + delta
        elif delta > 0:  # the start, or the pair left the queue: the nearest one on
            index = next((i for i, x in enumerate(ids) if sid is None or x > sid), len(ids))
        else:
            index = max((i for i, x in enumerate(ids) if sid is None or x < sid), default=-1)
        if not 0 <= index < len(ids):
            self._show(f"*End of the {md_text(self.w.split.value)} pairs ({len(ids)}).*")
            return
        self.open(ids[index])

    def open(self, sample_id: str) -> None:
        """Open one pair for review (into the draft, its frame on screen), with verdict controls
        bound to it as shown."""
        p = self.panel
        self.pairs.open_pair(sample_id)
        with p.session.lock:
            draft = p.editor.draft
            if draft.sample_id != sample_id:
                return  # the store refused it (notified)
            version = draft.base_version
        seen = latest_review(p.store, sample_id, version) if p.store is not None else None
        shown = Shown(sample_id, version, seen.op if seen is not None else None)
        with p.session.lock:
            self.current = shown
            self._bind(shown)
        self._show()

    def _bind(self, shown: Shown) -> None:
        """Replace *Approve*, *Reject* and their keys by controls bound to ``shown`` (same places
        in the folder; the old ones' clicks in flight find them removed)."""
        p, gui = self.panel, self.panel.session.client.gui
        old, self._controls = self._controls, []
        with p.session.client.atomic():
            for handle in old:
                handle.remove()
            with self.w.folder:
                for verdict, label, color, icon, order in (
                    ("approved", "Approve", "green", viser.Icon.CHECK, self.w.approve.order),
                    ("rejected", "Reject", "red", viser.Icon.X, self.w.reject.order),
                ):
                    button = gui.add_button(label, color=color, icon=icon, order=order)
                    button.on_click(self._act(verdict, shown))
                    self._controls.append(button)
            for verdict, key in (("approved", "approve"), ("rejected", "reject")):
                k = VERDICT_KEYS[key]
                try:
                    command = gui.add_command(k.label, hotkey=k.key, modifier=k.modifier)  # type: ignore[arg-type]
                except Exception:  # experimental in viser 1.1.1: the buttons still work
                    continue
                command.on_trigger(self._act(verdict, shown))
                self._controls.append(command)

    def _act(self, verdict: str, shown: Shown) -> Callable[[object], None]:
        """The callback of a verdict control bound to ``shown``."""
        return lambda _event: self.panel.guarded(lambda: self.verdict(verdict, shown))

    # ------------------------------------------------------------------ verdicts

    def verdict(self, verdict: str, shown: Shown | None = None) -> None:
        """Approve or reject the pair under review as ``shown`` (default: the one under review
        now)."""
        p = self.panel
        shown = shown if shown is not None else self.current
        if shown is None:
            p.notify("No pair under review", "Open one with Next (or key J).")
            return
        sid = shown.sample_id
        with p.session.lock:
            draft = p.editor.draft
            edited = draft.sample_id == sid and p.editor.history.can_undo
            reviewer, note = p.w.annotator.value, self.w.note.value
        if edited and verdict == "approved":
            p.notify(
                "The pair was edited",
                "Save the edit as a fix (Save fix, Shift+F), or undo it before approving.",
            )
            return
        if self._record(shown, verdict, reviewer, note):
            self.step(1)

    def save_fix(self) -> None:
        """Save the edited pair under review as a new version and record it ``fixed``."""
        p = self.panel
        if self.current is None:
            p.notify("No pair under review", "Open one with Next (or key J).")
            return
        sid = self.current.sample_id
        with p.session.lock:
            draft = p.editor.draft
            edited = draft.sample_id == sid and p.editor.history.can_undo
            reviewer, note = p.w.annotator.value, self.w.note.value
        if not edited:
            p.notify("Nothing to fix", "Edit the pair first; Approve records it as it is.")
            return
        result = self.pairs.save()
        if result is None:
            return
        if self._record(Shown(sid, result.version, None), "fixed", reviewer, note):
            self.step(1)

    def _record(self, shown: Shown, verdict: str, reviewer: str, note: str) -> bool:
        """Record the verdict on ``shown``; True only when this request wrote it (a repeated
        request is answered by the first: no second notification, no second step)."""
        p = self.panel
        store = p.store
        if store is None:
            p.notify("Reviewing is unavailable", str(p.hub.error), color="red")
            return False
        sid, version = shown.sample_id, shown.version
        key = f"{self._token}:{sid}:{version}:{shown.seen}:{verdict}"
        try:
            result = record_review(
                store,
                sid,
                verdict,
                reviewer,
                version=version,
                note=note,
                seen=shown.seen,
                request=key,
            )
        except ConflictError as exc:
            p.notify("Not recorded: the pair changed meanwhile", str(exc), color="red")
            if self.current is not None and self.current.sample_id == sid:
                self.open(sid)  # show what was decided, with controls bound to it
            return False
        except (StoreError, OSError, ValueError) as exc:
            p.notify("Review not recorded", str(exc), color="red")
            return False
        if result.repeated:
            return False
        self.w.note.value = ""
        p.notify(f"Pair {sid} {verdict}", f"Version {version}, by {reviewer or 'anonymous'}.")
        p.hub.pairs_changed()
        return True

    # ------------------------------------------------------------------ drawing

    def _show(self, message: str | None = None) -> None:
        w = self.w
        states = review_states(self.panel.store) if self.panel.store is not None else {}
        queue = self.queue()
        under = self.current is not None
        for handle in (*self._controls, w.fix):
            handle.disabled = not under
        if message is not None or self.current is None:
            w.status.content = message or "*Next opens the split's first pair.*"
            return
        sid, version = self.current.sample_id, self.current.version
        info = next((p for p, _ in queue if p.sample_id == sid), None)
        state = states.get(sid)
        where = ""
        ids = [p.sample_id for p, _ in queue]
        if sid in ids:
            where = f"pair {ids.index(sid) + 1} of {len(ids)} · "
        review = state.review if state is not None else None
        verdict = (
            f"{md_text(review.verdict)} by {md_text(review.reviewer)} (v{review.version})"
            if review is not None
            else "not reviewed yet"
        )
        shown = md_text(pair_option(info)) if info is not None else md_text(sid)
        w.status.content = f"**Reviewing** {where}{shown} (v{version}) · {verdict}"

    def _wire(self) -> None:
        w, p = self.w, self.panel

        @w.step.on_click
        def _(event: viser.GuiEvent) -> None:
            delta = -1 if event.target.value == PREVIOUS else 1
            p.guarded(lambda: self.step(delta))

        w.approve.on_click(lambda _e: p.guarded(lambda: self.verdict("approved")))
        w.reject.on_click(lambda _e: p.guarded(lambda: self.verdict("rejected")))
        for verdict, key in (("approved", "approve"), ("rejected", "reject")):
            k = VERDICT_KEYS[key]
            try:
                command = p.session.client.gui.add_command(
                    k.label,
                    hotkey=k.key,  # type: ignore[arg-type]
                    modifier=k.modifier,  # type: ignore[arg-type]
                )
            except Exception:  # experimental in viser 1.1.1: the buttons still work
                continue
            command.on_trigger(lambda _e, v=verdict: p.guarded(lambda: self.verdict(v)))
            self._controls.append(command)
        w.fix.on_click(lambda _e: p.guarded(self.save_fix))
