"""Run under ``torchrun``: both referent stages through ``model.training.loop.main``, each three times
(uninterrupted; stopped by a signal that only rank 1 receives; resumed), and write what happened
to a JSON file for tests/model/training/test_train_distributed.py (a helper, not a test module).

``python -m torch.distributed.run --standalone --nproc_per_node 2 tests/model/training/distributed_check.py
ROOT INIT_CHECKPOINT OUT``
"""

from __future__ import annotations

import json
import os
import signal
import sys
from pathlib import Path

import torch

import model.training.kinds as step_module
import model.training.loop as train_module
from model.checkpoint import load_checkpoint
from model.training import distributed
from model.training.state import load_run

STAGES = {
    "joint": ("referent_step", []),
    "freeze": ("cached_referent_step", ["--freeze-scene", "--init"]),
}


def _signal_on_rank_1(name: str, call: int) -> None:
    """Rank 1 sends itself SIGINT inside its ``call``-th step (rank 0 gets no signal)."""
    real = getattr(step_module, name)
    calls = [0]

    def step(*args):
        calls[0] += 1
        if calls[0] == call and distributed.rank() == 1:
            os.kill(os.getpid(), signal.SIGINT)
        return real(*args)

    setattr(step_module, name, step)


def main(root: str, init: str, out: str) -> None:
    distributed.init_from_env("cpu")
    torch.set_num_threads(1)
    # The guard of model.train's checkpoints: it must see ranks that differ.
    report: dict = {
        "guard": [
            distributed.same_on_every_rank([torch.ones(3)]),
            distributed.same_on_every_rank([torch.full((3,), float(distributed.rank()))]),
        ]
    }
    for stage, (step_name, flags) in STAGES.items():
        extra = [f if f != "--init" else f"--init={init}" for f in flags]
        common = ["--data", root, "--epochs", "2", "--batch-size", "1", "--val-every", "0"]
        common += ["--log-every", "1", "--prompts-per-scene", "4", "--bank-prompts", "8", *extra]
        whole, cut = Path(out) / f"{stage}-whole", Path(out) / f"{stage}-cut"
        codes = [train_module.main([*common, "--out", str(whole)])]
        real = getattr(step_module, step_name)  # the step functions each kind binds
        _signal_on_rank_1(step_name, call=1)
        codes.append(train_module.main([*common, "--out", str(cut)]))
        setattr(step_module, step_name, real)
        stopped = load_run(cut).progress
        codes.append(train_module.main([*common, "--out", str(cut), "--resume"]))
        distributed.barrier()
        if distributed.rank() == 0:
            run = load_run(cut)
            a = load_checkpoint(whole / "last.pt").state_dict()
            b = load_checkpoint(cut / "last.pt").state_dict()
            report[stage] = {
                "codes": codes,
                "stopped": [stopped.step, stopped.epoch, stopped.step_in_epoch],
                "step": run.progress.step,
                "world": run.world,
                "rng_differ": not torch.equal(run.rng[0]["torch"], run.rng[1]["torch"]),
                "equal": [k for k in a if not torch.equal(a[k], b[k])] == [],
                "loads": load_checkpoint(cut / "last.pt").checkpoint_metadata.step,
            }
        else:
            report[stage] = {"codes": codes}
    Path(out, f"report-{distributed.rank()}.json").write_text(json.dumps(report))
    distributed.close()


if __name__ == "__main__":
    main(*sys.argv[1:4])
