"""Training: the loss falls, checkpoints resume at the same step, DDP with 2 gloo processes,
and the evaluate command writes prediction files that the label reader parses."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from model.checkpoint import load_checkpoint
from model.training.loop import TrainConfig, cosine_lr, epoch_batches, train
from model.training.state import RunStateError
from scenes.frame.kitti import read_label_file
from scenes.synth.generate import SynthSettings, generate_root
from scenes.talk2radar.layout import LIDAR_FOLDER, split_file
from scenes.talk2radar.root import Talk2RadarRoot
from tests.paths import REPO


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("tiny") / "root"
    generate_root(root, 8, SynthSettings(seed=3), split_fractions=(0.5, 0.25, 0.25))
    return root


def _config(root: Path, out: Path, **kw) -> TrainConfig:
    base = dict(
        data=str(root),
        out=str(out),
        epochs=50,
        batch_size=2,
        val_every=0,
        warmup_steps=0,
        log_every=1,
        flip_probability=0.0,
        lr=2e-3,
        grounding="tpcnet",
    )
    base.update(kw)
    return TrainConfig(**base)


def _losses(out: Path) -> list[float]:
    lines = (out / "log.jsonl").read_text().splitlines()
    return [json.loads(line)["loss"] for line in lines if "loss" in json.loads(line)]


def test_schedule_and_sharding():
    assert cosine_lr(0, 100, 1e-3, 10) == pytest.approx(1e-4)
    assert cosine_lr(10, 100, 1e-3, 10) == pytest.approx(1e-3)
    assert cosine_lr(100, 100, 1e-3, 10) == pytest.approx(1e-5)
    a = epoch_batches(10, 2, epoch=3, seed=0, rank=0, world=2)
    b = epoch_batches(10, 2, epoch=3, seed=0, rank=1, world=2)
    assert len(a) == len(b) == 2
    assert not {i for batch in a for i in batch} & {
        i for batch in b for i in batch
    }  # ranks see disjoint samples
    assert a == epoch_batches(10, 2, epoch=3, seed=0, rank=0, world=2)  # the same on resume


def test_loss_falls_and_resume_continues(tiny_root, tmp_path):
    torch.manual_seed(0)
    out = tmp_path / "run"
    state = train(_config(tiny_root, out, max_steps=8))
    assert state.step == 8 and (out / "last.pt").is_file() and (out / "train_state.pt").is_file()
    losses = _losses(out)
    assert len(losses) == 8
    assert sum(losses[-2:]) < sum(losses[:2])
    resumed = train(_config(tiny_root, out, max_steps=10), resume=True)
    assert resumed.step == 10
    assert len(_losses(out)) == 10
    model = load_checkpoint(out / "last.pt")
    assert model.checkpoint_metadata.step == 10
    with pytest.raises(RunStateError, match=r"different settings.*lr"):
        train(_config(tiny_root, out, max_steps=12, lr=5e-3), resume=True)


def test_stop_epoch_keeps_the_planned_schedule(tiny_root, tmp_path):
    """``--stop-epoch`` cuts the budget without shortening the cosine schedule; a resume
    without it finishes the planned epochs."""
    out = tmp_path / "cut"
    samples = len(Talk2RadarRoot(tiny_root).ids("train"))
    steps_per_epoch = len(epoch_batches(samples, 2, epoch=0, seed=0, rank=0, world=1))
    cut = train(_config(tiny_root, out, epochs=3, stop_epoch=1, lr=1e-3))
    assert cut.epoch == 1 and cut.step == steps_per_epoch
    logged = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    total = 3 * steps_per_epoch
    last_lr = logged[-1]["lr"]
    assert last_lr == pytest.approx(cosine_lr(steps_per_epoch - 1, total, 1e-3, 0))
    assert last_lr > cosine_lr(steps_per_epoch - 1, steps_per_epoch, 1e-3, 0) * 1.5
    finished = train(_config(tiny_root, out, epochs=3, lr=1e-3), resume=True)
    assert finished.epoch == 3 and finished.step == total


@pytest.mark.slow
def test_torchrun_two_gloo_processes(tiny_root, tmp_path, torchrun):
    out = tmp_path / "ddp"
    args = ["-m", "model.train", "--grounding", "tpcnet", "--data", str(tiny_root)]
    args += ["--out", str(out), "--max-steps", "2", "--batch-size", "1", "--val-every", "0"]
    log = tmp_path / "torchrun.log"
    code = torchrun([*args, "--device", "cpu"], log, timeout=300)
    assert code == 0, log.read_text()[-3000:]
    assert (out / "last.pt").is_file()
    assert load_checkpoint(out / "last.pt").checkpoint_metadata.step == 2
    assert log.read_text().count("done: 2 steps") == 1  # only rank 0 reports


def test_evaluate_command_writes_parsable_files(tiny_root, tmp_path):
    out = tmp_path / "run"
    train(_config(tiny_root, out, max_steps=1))
    preds = tmp_path / "preds"
    report = tmp_path / "report.json"
    cmd = [
        sys.executable,
        "-m",
        "model.evaluate",
        "--data",
        str(tiny_root),
        "--split",
        "test",
        "--checkpoint",
        str(out / "last.pt"),
        "--out",
        str(preds),
        "--json",
        str(report),
    ]
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "mAP by prompt type" in done.stdout and "Entire annotated area" in done.stdout
    test_ids = split_file(tiny_root / LIDAR_FOLDER, "test").read_text().split()
    files = sorted(p.stem for p in preds.glob("*.txt"))
    assert files == sorted(test_ids)  # one file per frame, empty ones included
    for f in preds.glob("*.txt"):
        for label in read_label_file(f):
            assert label.score is not None and label.name in ("Car", "Pedestrian", "Cyclist")
    data = json.loads(report.read_text())
    assert {"entire_area", "roi", "by_prompt_type", "by_depth"} <= set(data)
    assert "Car_3d_all" in data["entire_area"] and "mAP_3d" in data["roi"]


def test_evaluate_rejects_an_empty_split(tiny_root, tmp_path):
    split_file(tiny_root / LIDAR_FOLDER, "empty").write_text("")
    cmd = [
        sys.executable,
        "-m",
        "model.evaluate",
        "--data",
        str(tiny_root),
        "--split",
        "empty",
        "--checkpoint",
        str(tmp_path / "missing.pt"),
        "--out",
        str(tmp_path / "p"),
    ]
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "no samples" in done.stderr
