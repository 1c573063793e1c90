"""What one browser sees of a frame: the 3D scene and the camera image.

- :mod:`~app.view.scene_view`: points, ego marker, range rings, camera presets and the View tab;
  :mod:`~app.view.point_sizes` (point sizes legible from every viewpoint);
- :mod:`~app.view.boxes_view`: 3D box wireframes (the answer's, the labelled objects', the
  Annotate tab's draft);
- :mod:`~app.view.camera_panel` and :mod:`~app.view.camera_image`: the camera image with the
  boxes and points projected into it;
- :mod:`~app.view.colors` (colour maps, class colours, legends) and :mod:`~app.view.color_vision`
  (how far apart two colours look, for every reader).
"""
