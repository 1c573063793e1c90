"""What the app serves: the root's kind, its frames and the shared current frame.

- :mod:`~app.serving.served`: the kind of root served, chosen once
  (:func:`~app.serving.served.serve_root` -> :class:`~app.serving.served.ServedRoot`), with
  :mod:`~app.serving.served_nuscenes` (a nuScenes root with its Talk2Car commands) and
  :mod:`~app.serving.labelled` (the frames' labelled boxes);
- :mod:`~app.serving.navigation`: the frames of the served split
  (:class:`~app.serving.navigation.FrameStore`, a :class:`~app.serving.navigation.Frame` with
  its ground estimate), the current frame every browser shares
  (:class:`~app.serving.navigation.Navigator`) and the Scene folder's controls;
- what a frame holds beyond its sensors: :mod:`~app.serving.ground_truth` (its labelled objects,
  and which one an answer's box overlaps) and :mod:`~app.serving.frame_commands` (its commands,
  listed under its summary, a click runs one).
"""
