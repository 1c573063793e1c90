"""Both referent-path stages under ``torchrun`` with 2 CPU processes (gloo; issue 24 item 2).

tests/model/training/distributed_check.py runs, in one ``torchrun`` launch, the joint stage and the
``--freeze-scene`` stage (on the shipped detector) through ``model.training.loop.main`` three times each:
uninterrupted; stopped by SIGINT that only rank 1 receives (both ranks must stop after the same
step, exit 130 and leave a resumable state with both ranks' RNG states); resumed. The resumed run
must equal the uninterrupted one bit for bit, and the checkpoint must load. Every checkpoint also
checks that the ranks hold the same weights (the gradients were averaged). The paper's path under
torchrun: tests/model/training/test_train.py.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from scenes.synth.generate import SynthSettings, generate_root
from tests.paths import REPO


@pytest.mark.slow
def test_both_referent_stages_train_stop_and_resume_under_torchrun(
    tmp_path: Path, torchrun
) -> None:
    root = tmp_path / "root"
    generate_root(root, 8, SynthSettings(seed=3, prompts_per_world=1), (0.5, 0.25, 0.25))
    out = tmp_path / "runs"
    out.mkdir()
    args = [str(Path(__file__).with_name("distributed_check.py")), str(root)]
    args += [str(REPO / "checkpoints" / "tpcnet-small.pt"), str(out)]
    log = tmp_path / "torchrun.log"
    code = torchrun(args, log, timeout=500)
    text = log.read_text()
    assert code == 0, text[-3000:]
    rank0 = json.loads((out / "report-0.json").read_text())
    rank1 = json.loads((out / "report-1.json").read_text())
    assert rank0["guard"] == rank1["guard"] == [True, False]
    for stage in ("joint", "freeze"):
        got = rank0[stage]
        assert got["codes"] == rank1[stage]["codes"] == [0, 130, 0], (stage, got)
        assert got["stopped"] == [1, 0, 1]  # after step 1 of 2 in epoch 0, on both ranks
        assert got["step"] == got["loads"] == 4 and got["world"] == 2
        assert got["rng_differ"]  # each rank's own RNG state is saved
        assert got["equal"], f"{stage}: the resumed run differs from the uninterrupted one"
    assert text.count("interrupted by SIGINT: stopped after step 1") == 2  # rank 0, per stage
    assert "Traceback" not in text


def test_amp_bf16_is_cuda_only(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from model.training.loop import main

    args = ["--data", str(tmp_path / "nowhere"), "--out", str(tmp_path / "run")]
    assert main([*args, "--amp", "bf16", "--device", "cpu"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: --amp bf16 runs on CUDA only (give --device cuda)"]


def test_every_stage_steps_under_bfloat16_autocast(tmp_path: Path, write_tiny_root) -> None:
    """What ``--amp bf16`` runs on CUDA, under the CPU's bfloat16 autocast (no GPU here): the
    outputs come out in bfloat16, the losses and the decoding run in float32, and the gradients
    are finite."""
    import numpy as np
    import torch

    from model import build_model
    from model.head.losses import grounding_loss
    from model.head.targets import collate_targets, draw_targets
    from model.training.config import PromptDraw
    from model.training.referent_cache import cache_scenes, cached_referent_step
    from model.training.referent_step import ReferentTrainConfig, float32_output, referent_step
    from model.training.start import init_from
    from scenes.datasets.frames import FrameDataset
    from scenes.datasets.grounding import GroundingDataset, collate

    root = tmp_path / "root"
    generate_root(root, 4, SynthSettings(seed=3, prompts_per_world=1), (0.5, 0.25, 0.25))
    cfg = ReferentTrainConfig(PromptDraw(4))
    model = build_model("small", grounding="referent")
    init_from(model, str(REPO / "checkpoints" / "tpcnet-small.pt"))
    scenes = FrameDataset(root, "train")
    frames = [scenes[i] for i in range(len(scenes))]
    cached, bank = cache_scenes(model, scenes, 8, progress=False)
    model.train()
    autocast = torch.autocast("cpu", torch.bfloat16)
    with autocast:
        joint = referent_step(model, frames, np.random.default_rng(0), cfg)
        frozen = cached_referent_step(model, cached, bank, np.random.default_rng(0), cfg)
    assert joint.prompts > 0 and frozen.prompts > 0
    for loss in (joint.total, frozen.total):
        assert loss.dtype == torch.float32 and torch.isfinite(loss)
    (joint.total + frozen.total).backward()
    paper = build_model("small", text_encoder="gru").train()
    batch = collate([GroundingDataset(root, "train")[0]])
    with autocast:
        out = paper(list(batch.lidar), list(batch.radar), list(batch.prompts))
    assert out.heatmap.dtype == torch.bfloat16
    targets = collate_targets(
        [draw_targets(batch.boxes[0], batch.classes[0], paper.head_grid, paper.cfg.head)]
    )
    terms = grounding_loss(float32_output(out), targets)
    assert terms.total.dtype == torch.float32 and torch.isfinite(terms.total)
    terms.total.backward()
    for m in (model, paper):
        grads = [p.grad for p in m.parameters() if p.grad is not None]
        assert grads and all(torch.isfinite(g).all() for g in grads)


def test_a_stopped_rank_ends_the_run_with_one_line(tmp_path: Path, torchrun, monkeypatch) -> None:
    """Rank 1 stopped (SIGSTOP) while rank 0 waits in a collective: within the rank timeout rank
    0 names it, kills it and exits 1; torchrun ends (it waited 150 s and more, silently)."""
    import time

    monkeypatch.setenv("TALK2PC_RANK_TIMEOUT", "3")
    log = tmp_path / "torchrun.log"
    start = time.monotonic()
    code = torchrun([str(Path(__file__).with_name("rank_stop_check.py"))], log, timeout=120)
    took = time.monotonic() - start
    text = log.read_text()
    lines = [line for line in text.splitlines() if line.startswith("error: rank")]
    assert code != 0 and len(lines) == 1, text[-3000:]
    assert lines[0].startswith("error: rank 1 (pid ") and "it was killed" in lines[0]
    assert "--resume" in lines[0] and "TALK2PC_RANK_TIMEOUT" in lines[0]
    assert took < 90, took


def test_the_rank_watch_names_a_rank_whose_heartbeat_stops() -> None:
    """Two ranks' watches over one store: while both beat, none is stopped; once rank 1 stops
    beating, rank 0 finds it after the limit; a rank that left (its beat 'done') is not."""
    import time

    from model.training.rank_watch import RankLiveness, RankWatch

    class Store:
        def __init__(self) -> None:
            self.data: dict[str, bytes] = {}

        def set(self, key: str, value: str) -> None:
            self.data[key] = value.encode()

        def get(self, key: str) -> bytes:
            return self.data[key]

        def check(self, keys: list[str]) -> bool:
            return all(k in self.data for k in keys)

    store, live = Store(), RankLiveness(0.2)
    zero, one = RankWatch(store, 0, 2, live), RankWatch(store, 1, 2, live)
    one._beat()
    assert zero.stopped_rank() is None
    time.sleep(0.1)
    one._beat()
    assert zero.stopped_rank() is None  # beating
    time.sleep(0.3)
    found = zero.stopped_rank()
    assert found is not None and found[0] == 1 and f":{os.getpid()}:" in found[1]
    one.stop()  # left normally: 'done'
    assert zero.stopped_rank() is None
    with pytest.raises(ValueError, match="TALK2PC_RANK_TIMEOUT='x'"):
        os.environ["TALK2PC_RANK_TIMEOUT"] = "x"
        try:
            RankLiveness.from_env()
        finally:
            del os.environ["TALK2PC_RANK_TIMEOUT"]


def test_a_rank_that_raises_exits_and_stops_beating() -> None:
    """A rank whose main thread ends on an uncaught exception without closing its watch: the
    watch stops within a beat and the process exits, so that torchrun sees the rank go (before,
    the watch thread kept the process alive and beating, and the other ranks waited for ever)."""
    import subprocess
    import sys
    import textwrap
    import time

    code = textwrap.dedent(
        """
        from model.training.rank_watch import RankLiveness, RankWatch

        class Store:
            def __init__(self):
                self.data = {}

            def set(self, key, value):
                self.data[key] = value.encode()

            def get(self, key):
                return self.data[key]

            def check(self, keys):
                return all(k in self.data for k in keys)

        RankWatch(Store(), 0, 1, RankLiveness(1.0)).start()
        raise RuntimeError("a bug in the step")
        """
    )
    start = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 1 and "a bug in the step" in done.stderr
    assert time.monotonic() - start < 30
