"""The C3D-RECHead detector and the paper's grounding through it: the head (``detector``:
``HeadConfig``, ``C3DRecHead``, ``HeadOutput``), its training targets and anchor points
(``targets``), decoding with rotated NMS (``decode``), the losses (``losses``) and the paper's
grounding head, DGGF + C3D-RECHead ranking (``paper``: ``PaperGrounding``)."""
