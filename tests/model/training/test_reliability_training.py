"""Interrupted training resumes exactly, a torn run is refused, and data that cannot train or
calibrate is refused with one line (issue 21, training side).

Every path is covered: the referent path's joint stage, its ``--freeze-scene`` stage (on the shipped
detector) and the paper's path (``--grounding tpcnet``). A signal is sent from inside a chosen step
(the step function wrapped), so that the stop falls mid-epoch at a known step.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest
import torch

import model.training.kinds as kinds_module
from model.checkpoint import load_checkpoint, read_checkpoint, save_checkpoint
from model.training.loop import TrainConfig, main, train
from model.training.state import LAST_FILE, STATE_FILE, RunState, load_run
from model.training.stop_signal import TrainingInterrupted
from scenes.synth.generate import SynthSettings, generate_root
from scenes.talk2radar.layout import LABEL, LIDAR_FOLDER, sample_dir
from tests.paths import REPO

SHIPPED = REPO / "checkpoints" / "tpcnet-small.pt"

PATHS = {
    "joint": {"grounding": "referent"},
    "freeze": {"grounding": "referent", "freeze_scene": True, "init": str(SHIPPED)},
    "tpcnet": {"grounding": "tpcnet"},
}
"""The three trainable stages."""
STEP_FUNCTION = {
    "joint": "referent_step",
    "freeze": "cached_referent_step",
    "tpcnet": "_forward_step",
}
"""The function of ``model.training.kinds`` that runs one step of each stage."""


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """8 synthetic frames with one prompt each: 4 training scenes (4 steps per epoch at batch 1)."""
    path = tmp_path_factory.mktemp("train21") / "root"
    generate_root(path, 8, SynthSettings(seed=3, prompts_per_world=1), (0.5, 0.25, 0.25))
    return path


def _config(root: Path, out: Path, stage: str, **kw: object) -> TrainConfig:
    base: dict = dict(
        data=str(root),
        out=str(out),
        epochs=2,
        batch_size=1,
        val_every=0,
        warmup_steps=0,
        log_every=1,
        prompts_per_scene=4,
        bank_prompts=8,
        lr=2e-3,
    )
    base.update(PATHS[stage], **kw)
    return TrainConfig(**base)


def _signal_during_step(monkeypatch: pytest.MonkeyPatch, stage: str, call: int, signum: int):
    """Send ``signum`` to this process from inside the ``call``-th step of ``stage``."""
    name = STEP_FUNCTION[stage]
    real = getattr(kinds_module, name)
    calls = [0]

    def step(*args):
        calls[0] += 1
        if calls[0] == call:
            os.kill(os.getpid(), signum)
        return real(*args)

    monkeypatch.setattr(kinds_module, name, step)


def _weights(run: Path) -> dict[str, torch.Tensor]:
    return load_checkpoint(run / LAST_FILE).state_dict()


@pytest.mark.parametrize("stage", ["joint", "freeze", "tpcnet"])
def test_signal_and_stop_epoch_then_resume_equal_an_uninterrupted_run(
    root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, stage: str
) -> None:
    before = signal.getsignal(signal.SIGINT)  # SIG_IGN where the suite runs as a background job
    whole = tmp_path / "whole"
    assert train(_config(root, whole, stage)).step == 8
    cut = tmp_path / "cut"
    with monkeypatch.context() as patched:
        _signal_during_step(patched, stage, call=3, signum=signal.SIGINT)
        with pytest.raises(TrainingInterrupted) as stopped:
            train(_config(root, cut, stage))
    assert stopped.value.exit_code == 130
    assert signal.getsignal(signal.SIGINT) is before  # handlers restored
    saved = load_run(cut)
    progress = saved.progress
    assert (progress.step, progress.epoch, progress.step_in_epoch) == (3, 0, 3)  # mid-epoch
    assert read_checkpoint(cut / LAST_FILE)["metadata"]["step"] == 3
    # Resume to the end of epoch 1 (--stop-epoch), then to the end: the uninterrupted weights.
    cut_epoch = train(_config(root, cut, stage, stop_epoch=1), resume=True)
    assert (cut_epoch.step, cut_epoch.epoch) == (4, 1)
    assert train(_config(root, cut, stage), resume=True).step == 8
    a, b = _weights(whole), _weights(cut)
    assert a.keys() == b.keys()
    different = [k for k in a if not torch.equal(a[k], b[k])]
    assert not different, f"{len(different)} tensors differ, e.g. {different[0]}"
    losses = [json.loads(x)["loss"] for x in (cut / "log.jsonl").read_text().splitlines()]
    wholes = [json.loads(x)["loss"] for x in (whole / "log.jsonl").read_text().splitlines()]
    assert losses == wholes  # every step's loss, not only the end
    if stage == "freeze":  # the referent stage learned, the frozen detector did not move
        init = read_checkpoint(SHIPPED)["state_dict"]
        moved = [k for k in a if k not in init or not torch.equal(a[k], init[k])]
        assert moved and all(k.startswith("referent.") for k in moved)


def test_signal_exits_130_with_one_line(
    root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "run"
    _signal_during_step(monkeypatch, "tpcnet", call=2, signum=signal.SIGINT)
    args = ["--data", str(root), "--out", str(out), "--grounding", "tpcnet", "--epochs", "3"]
    args += ["--batch-size", "1", "--val-every", "0", "--text-encoder", "gru"]
    assert main(args) == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if "interrupted" in line]
    assert len(lines) == 1 and lines[0].startswith("interrupted by SIGINT: stopped after step 2")
    assert str(out / STATE_FILE) in lines[0]
    assert load_run(out).progress.step == 2


def test_sigterm_to_the_command_finishes_the_step_and_exits_143(root: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "model.train", "--data", str(root), "--out", str(out)]
    cmd += ["--grounding", "tpcnet", "--text-encoder", "gru", "--epochs", "50", "--threads", "1"]
    cmd += ["--batch-size", "1", "--val-every", "0", "--log-every", "1"]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(REPO))
    proc = subprocess.Popen(
        cmd, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        log = out / "log.jsonl"
        deadline = time.monotonic() + 240
        while not (log.is_file() and log.read_text().strip()):
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()[1]
            time.sleep(0.2)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err[-2000:]
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("interrupted by SIGTERM: stopped after step "), last
    steps = [json.loads(x)["step"] for x in log.read_text().splitlines()]
    run = load_run(out)
    assert run.progress.step == steps[-1] >= 1  # every finished step is in the state
    assert read_checkpoint(out / LAST_FILE)["metadata"]["step"] == run.progress.step


def _old_layout(out: Path, run: RunState, step: int) -> None:
    """Write ``out/train_state.pt`` as the older layout did (no weights, no RNG): ``run`` at
    ``step``."""
    progress = dict(vars(run.progress), step=step)
    torch.save(
        {"config": run.config, "state": progress, "optimizer": run.optimizer}, out / STATE_FILE
    )


def test_a_torn_pair_is_refused_and_a_lagging_last_pt_is_rebuilt(
    root: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "run"
    args = ["--data", str(root), "--out", str(out), "--grounding", "tpcnet", "--epochs", "1"]
    args += ["--batch-size", "1", "--val-every", "0", "--text-encoder", "gru"]
    assert main([*args, "--max-steps", "2"]) == 0
    # A crash between the state and last.pt: last.pt behind. The state wins, last.pt follows it.
    state = load_run(out)
    stale = load_checkpoint(out / LAST_FILE)
    torch.nn.init.zeros_(next(stale.parameters()))
    save_checkpoint(out / LAST_FILE, stale, step=1)
    again = load_run(out)
    assert read_checkpoint(out / LAST_FILE)["metadata"]["step"] == 2
    rebuilt = read_checkpoint(out / LAST_FILE)["state_dict"]
    assert all(torch.equal(rebuilt[k], v) for k, v in state.model["state_dict"].items())
    assert again.progress.step == 2
    # The older layout: weights of step 2 in last.pt, the state of step 1 beside them.
    _old_layout(out, state, step=1)
    capsys.readouterr()
    before = (out / LAST_FILE).read_bytes(), (out / STATE_FILE).read_bytes()
    assert main([*args, "--max-steps", "4", "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "torn run" in err[0] and "step 2" in err[0] and "step 1" in err[0]
    assert ((out / LAST_FILE).read_bytes(), (out / STATE_FILE).read_bytes()) == before
    # The older layout of one step resumes (with a warning that it is not exact).
    _old_layout(out, state, step=2)
    assert main([*args, "--max-steps", "3", "--resume"]) == 0
    assert "without RNG states" in capsys.readouterr().err
    assert load_run(out).progress.step == 3
    (out / STATE_FILE).unlink()  # weights without a state: not resumable
    assert main([*args, "--max-steps", "4", "--resume"]) == 2
    assert "no train_state.pt beside it" in capsys.readouterr().err


def test_training_without_a_box_of_the_three_classes_exits_2(
    tmp_path: Path, write_tiny_root, capsys: pytest.CaptureFixture
) -> None:
    data = write_tiny_root(tmp_path / "root", frames=2)
    for label in sample_dir(data / LIDAR_FOLDER, LABEL).glob("*.txt"):
        label.write_text("")
    out = tmp_path / "run"
    args = ["--data", str(data), "--out", str(out), "--grounding", "tpcnet", "--epochs", "1"]
    assert main([*args, "--text-encoder", "gru", "--val-every", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no label of the 1 samples of split 'train'" in err[0], err
    assert not (out / LAST_FILE).exists()
    for label in sample_dir(data / LIDAR_FOLDER, LABEL).glob("*.txt"):  # other classes only
        label.write_text("DontCare 0 0 0 0 0 0 0 0 0 0 0 0 0 0\n")
    assert main([*args, "--text-encoder", "gru", "--val-every", "0"]) == 2


def test_resume_drops_log_records_of_steps_it_did_not_save(root: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    train(_config(root, out, "tpcnet", text_encoder="gru", max_steps=2))
    with open(out / "log.jsonl", "a") as handle:  # a kill after logging step 3, mid-line 4
        handle.write('{"step": 3, "loss": 1.0}\n{"step": 4, "lo')
    train(_config(root, out, "tpcnet", text_encoder="gru", max_steps=3), resume=True)
    lines = (out / "log.jsonl").read_text().splitlines()
    assert [json.loads(line)["step"] for line in lines] == [1, 2, 3]
    assert json.loads(lines[-1])["loss"] != 1.0


def test_resume_knows_the_run_folder_however_it_is_spelled(
    root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A run started with relative paths resumes with them spelled absolute, or through a
    symbolic link (issue 39: "--resume with different settings: ['out']"); another folder's
    run, or another root, is still refused."""
    from model.training.state import RunStateError

    monkeypatch.chdir(tmp_path)
    os.symlink(root, tmp_path / "root-link")
    relative = _config(Path(os.path.relpath(root)), Path("run"), "tpcnet", text_encoder="gru")
    train(replace(relative, max_steps=1))
    absolute = replace(relative, data=(str(tmp_path / "root-link"),), out=str(tmp_path / "run"))
    assert train(replace(absolute, max_steps=2), resume=True).step == 2
    other = tmp_path / "other-root"  # the same files, another root
    shutil.copytree(root, other)
    with pytest.raises(RunStateError, match=r"different settings: \['data'\]"):
        train(replace(absolute, data=(str(other),), max_steps=3), resume=True)
