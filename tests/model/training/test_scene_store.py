"""The ``--freeze-scene`` cache on disk (issue 48 item 1, model.training.scene_store): a second
run over the same root reads every scene and prompt back and trains to the same weights; an
interrupted or damaged cache is completed, never trusted; a cache that cannot be written never
stops a run; the keys follow what the cached values depend on."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from model.training import referent_cache
from model.training.scene_store import (
    TextStore,
    default_cache_dir,
    model_digest,
    scene_key,
)


def run(nusc: Path, out: Path, cache: str, *extra: str) -> int:
    from model.training.loop import main as train

    args = ["--data", str(nusc), "--talk2car", str(nusc / "commands"), "--freeze-scene"]
    args += ["--init-detector", "checkpoints/tpcnet-small.pt", "--epochs", "1", "--val-every"]
    args += ["0", "--no-calibrate", "--threads", "1", "--out", str(out), "--cache", cache]
    if "--label-prompts" not in extra:
        args += ["--label-prompts", "8"]  # few texts to encode: the test's time is the runs'
    return train([*args, *extra])


def weights(run_dir: Path) -> dict[str, torch.Tensor]:
    return torch.load(run_dir / "last.pt", weights_only=False)["state_dict"]


def scene_files(cache: Path) -> list[Path]:
    return sorted((cache / "scenes").rglob("*.pt"))


class Counting:
    """Wraps a function of :mod:`model.training.referent_cache`, counting its calls."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, name: str) -> None:
        self.calls = 0
        inner = getattr(referent_cache, name)

        def counted(*args, **kwargs):
            self.calls += 1
            return inner(*args, **kwargs)

        monkeypatch.setattr(referent_cache, name, counted)


@pytest.fixture(scope="module")
def first(nuscenes_training_root: Path, tmp_path_factory: pytest.TempPathFactory):
    """One run that filled an empty cache: ``(root, cache, run folder)``."""
    base = tmp_path_factory.mktemp("store")
    assert run(nuscenes_training_root, base / "run", str(base / "cache")) == 0
    return nuscenes_training_root, base / "cache", base / "run"


def test_a_second_run_reads_everything_back_and_trains_the_same_weights(
    first, tmp_path, monkeypatch
):
    nusc, cache, run_dir = first
    assert scene_files(cache) and (cache / "texts").is_dir()
    encode = Counting(monkeypatch, "scene_views")
    texts = Counting(monkeypatch, "encode_minilm_batched")
    assert run(nusc, tmp_path / "again", str(cache)) == 0
    assert encode.calls == 0 and texts.calls == 0  # nothing encoded again
    a, b = weights(run_dir), weights(tmp_path / "again")
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_an_interrupted_or_damaged_cache_is_completed(first, tmp_path, monkeypatch):
    nusc, cache, run_dir = first
    copy = tmp_path / "cache"
    import shutil

    shutil.copytree(cache, copy)
    files = scene_files(copy)
    files[0].unlink()  # a pass killed before this scene
    files[1].write_bytes(files[1].read_bytes()[:100])  # a torn file
    encode = Counting(monkeypatch, "scene_views")
    assert run(nusc, tmp_path / "again", str(copy)) == 0
    assert encode.calls == 2  # only those two encoded again
    assert len(scene_files(copy)) == len(files)
    a, b = weights(run_dir), weights(tmp_path / "again")
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_cache_none_keeps_nothing_and_an_unwritable_cache_never_stops_a_run(
    nuscenes_training_root, tmp_path, capsys
):
    blocked = tmp_path / "a-file"
    blocked.write_text("not a folder")
    assert run(nuscenes_training_root, tmp_path / "r1", str(blocked)) == 0
    said = capsys.readouterr().err
    assert said.count("cannot write") == 1 and str(blocked) in said  # said once, the run went on
    assert (tmp_path / "r1" / "last.pt").is_file()
    assert run(nuscenes_training_root, tmp_path / "r2", "none") == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file", "r1", "r2"]


def test_the_default_folder(monkeypatch, tmp_path):
    monkeypatch.setenv("TALK2PC_CACHE", str(tmp_path / "c"))
    assert default_cache_dir() == tmp_path / "c"
    monkeypatch.delenv("TALK2PC_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "x"))
    assert default_cache_dir() == tmp_path / "x" / "talk2pc"


def test_the_model_key_follows_the_detector_not_the_referent_stage(untrained_model):
    """The candidates never read the referent stage (which a --freeze-scene run trains), so the
    store's model key leaves it out; every other tensor is in it."""
    model = untrained_model("referent")
    lidar = np.random.default_rng(0).uniform(-1, 30, (3000, 4)).astype(np.float32)
    radar = np.zeros((0, 7), np.float32)
    before = referent_cache.scene_views(model, lidar, radar, [], False)[0]
    key = model_digest(model)
    with torch.no_grad():
        for p in model.grounding.parameters():
            p.add_(1.0)
    after = referent_cache.scene_views(model, lidar, radar, [], False)[0]
    assert model_digest(model) == key
    for name in ("geometry", "fused", "lidar", "radar"):
        x, y = getattr(before, name), getattr(after, name)
        assert (x is None and y is None) or torch.equal(x, y)
    with torch.no_grad():
        next(model.scene.parameters()).add_(1e-3)
    assert model_digest(model) != key


def test_the_scene_key_follows_the_scene(nuscenes_training_root):
    from scenes.datasets.nuscenes_frames import NuScenesFrames, open_talk2car

    nusc = nuscenes_training_root
    item = NuScenesFrames(*open_talk2car(nusc, nusc / "commands", "train")).item(0)
    key = scene_key(item, True)
    assert scene_key(item, True) == key
    moved = item.lidar.copy()
    moved[0, 0] += 0.01
    assert scene_key(dataclasses.replace(item, lidar=moved), True) != key
    assert scene_key(item, False) != key  # without its labelled view


def test_a_run_of_other_prompt_settings_shares_the_scenes(first, tmp_path, monkeypatch):
    """The prompts are drawn by each run; only the encoded scenes are kept."""
    nusc, cache, _ = first
    encode = Counting(monkeypatch, "scene_views")
    assert run(nusc, tmp_path / "r", str(cache), "--label-prompts", "5", "--seed", "3") == 0
    assert encode.calls == 0


def test_stored_texts_come_back_and_a_torn_index_line_is_only_unused(tmp_path):
    store = TextStore(tmp_path / "t")
    a = (torch.ones(3, 2, dtype=torch.float16), torch.zeros(3, 1), False)
    b = (torch.full((2, 2), 2.0, dtype=torch.float16), torch.ones(2, 1), True)
    store.save({"the car": a})
    store.save({"the bus": b})
    with (store.folder / "index.jsonl").open("a") as handle:
        handle.write('{"file": "x.pt", "te')  # a kill in the middle of an append
    found = TextStore(tmp_path / "t").load(["the car", "the bus", "the tram"])
    assert sorted(found) == ["the bus", "the car"]
    assert torch.equal(found["the bus"][0], b[0]) and found["the bus"][2] is True


def test_a_cache_inside_the_training_root_is_refused(nuscenes_training_root, tmp_path, capsys):
    """The root's files are the user's (a release): a --cache in or over it is refused with one
    line before anything is written there."""
    from model.training.loop import main as train

    nusc = nuscenes_training_root
    before = sorted(p.relative_to(nusc) for p in nusc.rglob("*"))
    args = ["--data", str(nusc), "--talk2car", str(nusc / "commands"), "--freeze-scene"]
    args += ["--init-detector", "checkpoints/tpcnet-small.pt", "--epochs", "1", "--val-every"]
    args += ["0", "--no-calibrate", "--threads", "1", "--out", str(tmp_path / "run")]
    for cache in (nusc / "cache", nusc / "commands", nusc.parent):
        assert train([*args, "--cache", str(cache)]) == 2
        said = capsys.readouterr().err.strip().splitlines()
        assert said[-1].count("--cache") == 1 and str(nusc) in said[-1]
    assert sorted(p.relative_to(nusc) for p in nusc.rglob("*")) == before
