"""The referent path: which of a scene's object candidates a sentence refers to. The referent
stage (``stage``: ``ReferentStage``, ``referent_loss``), what a candidate carries (``candidates``:
geometry and point evidence; ``scene_candidates``: one scene's candidates, their batching and the
answer's heatmap), labelled boxes as candidates (``labelled``) and the grounding head over the
detector's proposals (``head``: ``ReferentGrounding``)."""
