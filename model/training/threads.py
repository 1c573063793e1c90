"""torch's CPU threads of a ``--freeze-scene`` run (``python -m model.train --threads``, 0: chosen
here by :func:`freeze_scene_threads` from what other processes keep busy, :func:`machine_load`)."""

from __future__ import annotations

import os
import time

FREEZE_SCENE_THREADS = 1
"""torch's CPU threads of a ``--freeze-scene`` run when ``--threads`` is not given and other jobs
hold the cores (:func:`freeze_scene_threads`). Its steps are many small operations on cached
candidates, and torch's thread pool slows down several times over when another job takes a core:
measured on the 2-core machine with another training job running, 8 cached nuScenes scenes and
80 steps took 50 s with 1 thread against 209 s with 2 (docs/RESULTS_HISTORY.md, "Talk2Car on synthetic
nuScenes roots")."""

IDLE_LOAD = 0.5
"""Other processes keeping less than this many cores busy is an idle machine
(:func:`freeze_scene_threads`, :func:`machine_load`)."""


def _cpu_jiffies() -> tuple[int, int]:
    """``(busy, total)`` of /proc/stat's ``cpu`` line (every core together)."""
    with open("/proc/stat") as handle:
        fields = [int(v) for v in handle.readline().split()[1:9]]
    idle = fields[3] + fields[4]  # idle, iowait
    return sum(fields) - idle, sum(fields)


def machine_load(window: float = 0.5) -> float:
    """How many cores other processes keep busy now: /proc/stat's busy share over ``window``
    seconds times the cores, less this process's own CPU time over it. Now, not the 1-minute
    load average: a job that has just ended (the converter that wrote the root a moment ago)
    does not count, one still running does. Where /proc/stat cannot be read, the 1-minute load
    average."""
    try:
        busy0, total0 = _cpu_jiffies()
        own0, start = time.process_time(), time.monotonic()
        time.sleep(window)
        busy1, total1 = _cpu_jiffies()
        own = (time.process_time() - own0) / max(time.monotonic() - start, 1e-6)
    except (OSError, ValueError, IndexError):
        return os.getloadavg()[0]
    cores = os.cpu_count() or 1
    share = (busy1 - busy0) / max(total1 - total0, 1)
    return max(0.0, share * cores - own)


def freeze_scene_threads(load: float, cores: int, processes: int = 1) -> int:
    """torch's CPU threads of a ``--freeze-scene`` run when ``--threads`` is not given: on an idle
    machine (``load``, the cores others keep busy, :func:`machine_load`, below :data:`IDLE_LOAD`) the cores shared
    between the run's ``processes`` on this machine (torchrun's ranks), else
    :data:`FREEZE_SCENE_THREADS`. Idle, the second core pays: 8 cached nuScenes scenes, 120 steps
    ran at 3.3 steps a second with 1 thread and 5.0 with 2 on the 2-core machine."""
    if load >= IDLE_LOAD:
        return FREEZE_SCENE_THREADS
    return max(1, cores // max(1, processes))


__all__ = ["FREEZE_SCENE_THREADS", "IDLE_LOAD", "freeze_scene_threads", "machine_load"]
