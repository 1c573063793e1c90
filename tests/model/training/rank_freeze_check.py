"""Run under ``torchrun`` (a helper of tests/model/training/test_reliability5_frozen_rank.py, not a test module):
both ranks time short steps as the training loop does (``distributed.note_step``), then rank 1
stops itself (SIGSTOP); rank 0 waits in the next collective, where only the rank watch
(model/training/rank_watch.py), its limit set from the steps' duration, can end it.

``python -m torch.distributed.run --nproc_per_node 2 tests/model/training/rank_freeze_check.py STEPS STEP_S``
"""

from __future__ import annotations

import os
import signal
import sys
import time

from model.training import distributed

if __name__ == "__main__":
    steps, step_s = int(sys.argv[1]), float(sys.argv[2])
    distributed.init_from_env("cpu")
    for _ in range(steps):
        began = time.perf_counter()
        time.sleep(step_s)
        distributed.barrier()
        distributed.note_step(time.perf_counter() - began)
    if distributed.rank() == 1:
        print(f"rank 1 stops at {time.time():.3f}", flush=True)
        os.kill(os.getpid(), signal.SIGSTOP)
    distributed.barrier()  # rank 0 waits here for a rank that cannot come
    distributed.close()
