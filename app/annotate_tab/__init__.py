"""The "Annotate" tab: build prompt-to-box pairs in the browser and save them into the served root.

A thin layer over :mod:`annotate` (drafts with undo / redo, validation, fitting, evidence, prompt
suggestion, proposals from predictions, the atomic store); nothing here re-implements them. The
app (:class:`app.server.Talk2PCApp`) passes :func:`build_annotation_tab` to every browser's
session as its "Annotate" tab.

The parts:

- :mod:`~app.annotate_tab.hub`: :class:`AnnotationHub`, what every browser shares, owned by the
  app object: the served root's :class:`annotate.AnnotationStore` and the open tabs.
- :mod:`~app.annotate_tab.panel`: :class:`AnnotationPanel`, one browser's state (its own
  :class:`annotate.DraftEditor`, selection, the draft's frame) and its drawing, refreshed part by
  part (:class:`~app.annotate_tab.panel.Part`: view, evidence, checks, ...).
- :mod:`~app.annotate_tab.edits` and :mod:`~app.annotate_tab.pairs`: what the person does (edit
  the draft; save, reopen, delete pairs).
- :mod:`~app.annotate_tab.widgets`, :mod:`~app.annotate_tab.formatting`,
  :mod:`~app.annotate_tab.view`: the widgets, the text they show, the draft boxes and the gizmo in
  ``client.scene``; :mod:`~app.annotate_tab.tab` wires them together.

Pairs are saved into the root being served; after a save or a deletion the split is re-read
(:meth:`app.navigation.Navigator.reload`) and every browser's list of saved pairs is refreshed.

Using it with the mouse only:

- **Click the ground** (with *Click to place* on) to place a box of the *New box class* at its
  typical size (:func:`annotate.default_box`) standing on the frame's ground estimate; the new box
  is selected. A click inside a draft box's footprint selects that box instead.
- **Drag the gizmo** of the selected box: its arrows and square move it on the ground, its ring
  turns it (yaw). One drag is one undo step (:class:`annotate.DraftEditor`'s ``merge_key``).
- *Box* picks the selected box; *Class*, *Length*, *Width*, *Height*, *Yaw (deg)* edit it (the
  bottom stays on the ground when the height changes); *Fit to points* fits it to the LiDAR
  points around it (:func:`annotate.fit_box`); *Delete box* removes it. *Use predictions* turns
  the boxes of the last answer (Query tab) on this frame into draft boxes.
- The evidence table gives, per box, the LiDAR and radar points inside, the mean compensated
  radial velocity and what its sign means, and the distance (:func:`annotate.box_evidence`).
- *Pair prompt* holds the sentence; *Suggest* writes one from the boxes
  (:func:`annotate.suggest_prompt`), to edit; *Refers to nothing* marks a prompt with no referent.
- *Save pair* writes the pair (split and annotator name beside it); problems found by
  :func:`annotate.validate` are listed under it before saving and shown as a notification with
  the exact messages when saving is refused. *Draft*: Undo, Redo, New pair.
- *Saved pairs* lists the pairs of the root (re-read on every page load); *Open pair* reopens
  one into the draft (saving then writes a new version), *Delete pair* removes it (after a
  confirmation).

Hotkeys: viser 1.1.1 has experimental commands (``gui.add_command``) with hotkeys, also listed in
its command palette (Ctrl/Cmd+K). :data:`~app.annotate_tab.widgets.HOTKEYS` registers Undo, Redo, Delete box and Save pair.

The frame of a draft. Navigation is shared by every browser, so the frame on screen can change
under a draft. A draft belongs to the frame it was started on (for a reopened pair: the pair's
sample and the frame it was annotated on). While another frame is shown its boxes are hidden, a
click on the ground does nothing but say so, and *Back to the draft's frame* returns to it;
saving still saves it on its own frame. An empty draft simply follows the frame on screen.

After a successful save the draft is emptied (a new pair on the frame on screen).
"""

from app.annotate_tab.hub import AnnotationHub
from app.annotate_tab.panel import AnnotationPanel, DraftFrame, Part
from app.annotate_tab.tab import build_annotation_tab

__all__ = ["AnnotationHub", "AnnotationPanel", "DraftFrame", "Part", "build_annotation_tab"]
