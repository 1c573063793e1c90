"""nuScenes and Talk2Car as the releases come: the 23 categories and their model classes
(:mod:`~scenes.nuscenes.classes`), the 13 JSON tables (:mod:`~scenes.nuscenes.tables`), the
sensor files (:mod:`~scenes.nuscenes.sensorfiles`: LIDAR_TOP ``.pcd.bin``, radar PCD v0.7),
poses and frames (:mod:`~scenes.nuscenes.geometry`), the reader (:mod:`~scenes.nuscenes.root`:
``NuScenesRoot``, ``NuScenesFrame``), the Talk2Car command files
(:mod:`~scenes.nuscenes.talk2car`) and the writer of a synthetic root
(:mod:`~scenes.nuscenes.writer`, :mod:`~scenes.nuscenes.export`). docs/TALK2CAR.md says how
nuScenes maps onto the model's frame and channels."""
