"""Run under ``torchrun`` (a helper of tests/model/training/test_train_distributed.py, not a test module): rank 1
stops itself (SIGSTOP) after a first barrier; rank 0 waits in the next one, where only the rank
watch (model/training/rank_watch.py) can end it.

``python -m torch.distributed.run --nproc_per_node 2 tests/model/training/rank_stop_check.py``
"""

from __future__ import annotations

import os
import signal

from model.training import distributed

if __name__ == "__main__":
    distributed.init_from_env("cpu")
    distributed.barrier()
    if distributed.rank() == 1:
        os.kill(os.getpid(), signal.SIGSTOP)
    distributed.barrier()  # rank 0 waits here for a rank that cannot come
    distributed.close()
