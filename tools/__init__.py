"""Data tools users are told to run: commands that write roots or pictures beside the product.

``nuscenes_converter`` (a synthetic root as someone else's converter would write nuScenes and
Talk2Car, from the release's facts alone, not ``scenes.nuscenes``' writer), ``unlabelled_root``
(a root's sensor files only, as an unlabelled recording comes: what ``model.adapt`` reads) and
``camera_shot`` (the camera panel's documentation screenshot, in a real browser). They import
``scenes`` (and ``camera_shot`` ``app`` and ``launch``); nothing but the tests imports them.
"""
