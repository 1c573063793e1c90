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

Pairs are saved into the root being served when it is a Talk2Radar root with prompts, else
into the folder named with ``launch.py --pairs`` (a root without prompts served without it saves
nothing and suggests :func:`app.serving.served.default_pairs_root`); the status line says where. Nothing
is written before the first save. After a save or a deletion into the served root its split is re-read
(:meth:`app.serving.navigation.Navigator.reload`); every browser's list of saved pairs is refreshed.

Using it (a one-box pair: a click and the sentence; see docs/ANNOTATION.md):

- **Click the ground** (with *Click to place* on) to place a box of the *New box class* at its
  typical size (:func:`annotate.default_box`) standing on the frame's ground estimate; the new box
  is selected. A click inside a draft box's footprint selects that box instead; a click on a
  ready-made box (below) adds it. On a frame with labelled boxes (sentence first) a click on no
  box places nothing and says so; Shift+click places a box anywhere. A box that could not be
  saved where it would go (outside the annotated range or the camera's view) is not placed: a
  notification says why at once.
- **Ready-made boxes**: on a root without prompts (View-of-Delft as released) the frame's
  label_2 objects of the metric classes that are not in the draft are drawn (``"+ Car"``) and
  listed under *Object* (nearest first); *Add object* or a click on one adds it.
- **Two class controls**: *New box class* is the class of the next box placed and nothing else
  (choosing it never changes a placed box: the box just placed stays selected, and an annotator
  choosing the next class must not relabel it); *Change class* (Boxes folder, shown while a box
  is selected) relabels the selected box, one undo step.
- **Drag the gizmo** of the selected box: its arrows and square move it on the ground, its ring
  turns it (yaw). One drag is one undo step (:class:`annotate.DraftEditor`'s ``merge_key``).
- *Box* picks the selected box; *Length*, *Width*, *Height*, *Yaw (deg)* edit it (the bottom
  stays on the ground when the height changes); *Fit to points* fits it to the LiDAR points
  around it (:func:`annotate.fit_box`); *Delete box* removes it. These are shown only while a box
  is selected. *Use predictions* turns the boxes of the last answer (Query tab) on this frame into
  draft boxes.
- The evidence table gives, per box, the LiDAR and radar points inside, the mean compensated
  radial velocity and what its sign means, and the distance (:func:`annotate.box_evidence`).
- *Pair prompt* (at the top, beside *Save pair*) holds the sentence; **Enter** in it saves the
  pair when nothing blocks it (else a notification lists what does); **Esc** leaves the field
  (:mod:`app.keys`), so the next click or hotkey does not type. *Suggest* writes a sentence from
  the boxes (:func:`annotate.suggest_prompt`), to edit; *Refers to nothing* marks a prompt with no
  referent.
- *Save pair* is disabled, with what :func:`annotate.validate` still objects to listed under it,
  until the draft can be saved; after a save the status line names the pair written and the box
  fields are hidden (a new, empty draft). *Save options*: the split and the annotator's name.
  *Draft*: Undo, Redo, New pair.
- *Saved pairs* lists the pairs of the store (re-read on every page load); *Open pair* reopens
  one into the draft (saving then writes a new version), *Delete pair* removes it (after a
  confirmation).
- **Sentence first on labelled frames** (:mod:`~app.annotate_tab.referents`; a View-of-Delft
  root, or ``--scene-labels``, with a referent-path model): typing the sentence picks its
  referents among the frame's labelled boxes; a click on a labelled box toggles it; Enter saves
  only a pick made for the sentence as it is.
- *Sequence* (:mod:`~app.annotate_tab.sequence`, on splits with pose files): play a drive,
  step through it, and *Carry to next frame* (:mod:`annotate.carry`).
- *Review* (:mod:`~app.annotate_tab.review`): walk a split's saved pairs; approve, reject, or
  save a fix, each a ``review`` line of the manifest (:mod:`annotate.review`).
- The draft is drawn into the camera panel too (its ``draft`` layer,
  :func:`~app.annotate_tab.view.draft_layer`).

Keys (:mod:`~app.annotate_tab.keys`): every step of a pair but the ground click has a key
(:data:`~app.annotate_tab.keys.KEYS`: viser 1.1.1's experimental commands, ``gui.add_command``,
also listed in its command palette, Ctrl/Cmd+K; they act while no text field has the focus, Esc
leaves one), P puts the cursor in *Pair prompt*, and the *Keys* folder and key H list them all.

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
