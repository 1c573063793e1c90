"""Cross-checks against the official devkits, each installed in a scratch interpreter (not a
project dependency): ``compare_vod_devkit`` (the VoD metric; its devkit side
``vod_devkit_worker`` runs under the devkit's interpreter) and ``compare_nuscenes_devkit`` (the
nuScenes and Talk2Car reader). Run as scripts: ``python bench/devkit/<name>.py``.
"""
