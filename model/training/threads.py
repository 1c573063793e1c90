"""torch's CPU threads of a ``--freeze-scene`` run (``python -m model.train --threads``, 0: chosen
here by :func:`freeze_scene_threads` from the machine's load)."""

from __future__ import annotations

FREEZE_SCENE_THREADS = 1
"""torch's CPU threads of a ``--freeze-scene`` run when ``--threads`` is not given and other jobs
hold the cores (:func:`freeze_scene_threads`). Its steps are many small operations on cached
candidates, and torch's thread pool slows down several times over when another job takes a core:
measured on the 2-core machine with another training job running, 8 cached nuScenes scenes and
80 steps took 50 s with 1 thread against 209 s with 2 (docs/RESULTS_HISTORY.md, "Talk2Car on synthetic
nuScenes roots")."""

IDLE_LOAD = 0.5
"""A 1-minute load average below this is an idle machine (:func:`freeze_scene_threads`)."""


def freeze_scene_threads(load: float, cores: int, processes: int = 1) -> int:
    """torch's CPU threads of a ``--freeze-scene`` run when ``--threads`` is not given: on an idle
    machine (``load``, the 1-minute load average, below :data:`IDLE_LOAD`) the cores shared
    between the run's ``processes`` on this machine (torchrun's ranks), else
    :data:`FREEZE_SCENE_THREADS`. Idle, the second core pays: 8 cached nuScenes scenes, 120 steps
    ran at 3.3 steps a second with 1 thread and 5.0 with 2 on the 2-core machine."""
    if load >= IDLE_LOAD:
        return FREEZE_SCENE_THREADS
    return max(1, cores // max(1, processes))


__all__ = ["FREEZE_SCENE_THREADS", "IDLE_LOAD", "freeze_scene_threads"]
