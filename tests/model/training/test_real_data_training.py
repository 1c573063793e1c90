"""Training the referent path on roots as the real releases come: no sidecar, given prompts,
labels as detection targets, several roots with weights, --init-detector."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from model.checkpoint import load_checkpoint
from model.training.data import DataSpecError, MixedFrames, root_specs
from model.training.loop import main
from model.training.start import SCENE_MODULES
from scenes.datasets.frames import FrameDataset
from scenes.synth.generate import SynthSettings, generate_root
from scenes.talk2radar.layout import meta_dir


@pytest.fixture(scope="module")
def synth_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("synth") / "root"
    generate_root(root, 6, SynthSettings(seed=5), split_fractions=(0.67, 0.0, 0.33))
    return root


@pytest.fixture(scope="module")
def release_root(synth_root, tmp_path_factory) -> Path:
    """The synthetic root without its sidecar, as a release comes."""
    root = tmp_path_factory.mktemp("release") / "root"
    shutil.copytree(synth_root, root, ignore=shutil.ignore_patterns("meta", "sources"))
    assert not meta_dir(root).exists()
    return root


def test_root_specs_pair_in_order():
    specs = root_specs(["a", "b"], [2.0], ["none", "vod"])
    assert [(s.path, s.weight, s.scene_labels) for s in specs] == [
        ("a", 2.0, None),
        ("b", 1.0, "vod"),
    ]
    with pytest.raises(DataSpecError, match="--data-weight"):
        root_specs(["a"], [1.0, 2.0])
    with pytest.raises(DataSpecError, match="> 0"):
        root_specs(["a"], [float("nan")])
    with pytest.raises(DataSpecError, match="at least one"):
        root_specs([])


def test_labels_source_never_reads_the_sidecar(synth_root, tmp_path):
    root = tmp_path / "root"
    shutil.copytree(synth_root, root)
    for path in meta_dir(root).glob("*.json"):
        path.write_text("{ not json")  # reading any sidecar would now raise
    frames = FrameDataset(root, "train", source="labels")
    assert frames.source == "labels"
    item = frames[0]
    assert item.from_labels and not item.generates_prompts
    assert item.given and item.given[0].text
    sample = frames.root.load(item.sample_id)
    assert len(item.given[0].referent_ids) == len(sample.boxes)
    for ref in item.given[0].referent_ids:
        assert np.min(np.abs(sample.boxes - item.actors[ref].box).sum(axis=1)) < 1e-9


def test_auto_source_is_labels_without_a_meta_folder(release_root, synth_root, capsys):
    assert FrameDataset(release_root, "train").source == "labels"
    assert "no scene labels given" in capsys.readouterr().err
    assert FrameDataset(synth_root, "train").source == "sidecar"


def test_mixed_frames_weights(synth_root, release_root):
    a = FrameDataset(synth_root, "train")
    b = FrameDataset(release_root, "train")
    mixed = MixedFrames([a, b], [1.0, 2.5], seed=1)
    expected = len(a) + 2 * len(b) + round(0.5 * len(b))
    assert len(mixed) == expected
    counts = np.bincount([mixed.resolve(j) for j in range(len(mixed))], minlength=len(a) + len(b))
    assert np.all(counts[: len(a)] == 1) and np.all(counts[len(a) :] >= 2)
    first = mixed.table.copy()
    mixed.set_epoch(1)
    mixed.set_epoch(0)
    assert np.array_equal(first, mixed.table)
    assert mixed[len(a)].from_labels and not mixed[0].from_labels


def test_scene_labels_bring_label_prompts_by_default():
    from model.training.config import LABEL_PROMPTS, LABELLED_PROMPTS_PER_SCENE, TrainConfig

    labelled = TrainConfig(data=("t2r",), out="runs/x", scene_labels=("vod",))
    assert labelled.label_prompts == LABEL_PROMPTS > 0
    assert labelled.prompts_per_scene == LABELLED_PROMPTS_PER_SCENE
    plain = TrainConfig(data=("synth",), out="runs/x")
    assert (plain.label_prompts, plain.prompts_per_scene) == (0, 8)
    mixed = TrainConfig(data=("synth", "t2r"), out="runs/x", scene_labels=("none", "vod"))
    assert (mixed.label_prompts, mixed.prompts_per_scene) == (LABEL_PROMPTS, 8)
    given = TrainConfig(
        data=("t2r",), out="runs/x", scene_labels=("vod",), label_prompts=0, prompts_per_scene=2
    )
    assert (given.label_prompts, given.prompts_per_scene) == (0, 2)


def test_freeze_scene_with_init_detector_on_a_release_root(release_root, tmp_path):
    out = tmp_path / "run"
    torch.manual_seed(0)
    code = main(
        [
            "--data",
            str(release_root),
            "--freeze-scene",
            "--init-detector",
            "checkpoints/tpcnet-small.pt",
            "--epochs",
            "2",
            "--val-every",
            "0",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    trained = load_checkpoint(out / "last.pt")
    shipped = load_checkpoint("checkpoints/tpcnet-small.pt")
    own, ref = trained.state_dict(), shipped.state_dict()
    scene = [k for k in own if k.startswith(SCENE_MODULES)]
    assert scene and all(torch.equal(own[k], ref[k]) for k in scene)
    referent = [k for k in own if k.startswith("referent.")]
    assert referent and not all(torch.equal(own[k], ref[k]) for k in referent)


def test_init_detector_over_init_takes_each_part_from_its_own_checkpoint(release_root, tmp_path):
    """``--init A --init-detector B``: the scene encoder and detector are B's, the referent stage
    A's (a retrained detector under an earlier referent stage); any other pair is refused."""
    from model.checkpoint import save_checkpoint
    from model.training.config import TrainConfig, TrainingError
    from model.training.start import start_model

    shipped = load_checkpoint("checkpoints/tpcnet-small.pt")
    other = load_checkpoint("checkpoints/tpcnet-small.pt")
    with torch.no_grad():
        for tensor in other.state_dict().values():
            if tensor.is_floating_point():
                tensor.add_(1.0)
    detector = save_checkpoint(tmp_path / "detector.pt", other)
    cfg = TrainConfig(
        data=(str(release_root),),
        out=str(tmp_path / "run"),
        init="checkpoints/tpcnet-small.pt",
        init_detector=str(detector),
    )
    model, _, _ = start_model(cfg, False, 0, 1, torch.device("cpu"))
    own, ref, moved = model.state_dict(), shipped.state_dict(), other.state_dict()
    scene = [k for k in own if k.startswith(SCENE_MODULES) and own[k].is_floating_point()]
    referent = [k for k in own if k.startswith("referent.") and own[k].is_floating_point()]
    assert scene and all(torch.equal(own[k], moved[k]) for k in scene)
    assert referent and all(torch.equal(own[k], ref[k]) for k in referent)
    with pytest.raises(TrainingError, match="not --init-detector and --init-other-classes"):
        TrainConfig(
            data=(str(release_root),),
            out="runs/x",
            init_detector=str(detector),
            init_other_classes=str(detector),
        )


def test_joint_training_on_a_release_and_a_synthetic_root(synth_root, release_root, tmp_path):
    out = tmp_path / "run"
    code = main(
        [
            "--data",
            str(synth_root),
            "--data",
            str(release_root),
            "--data-weight",
            "1",
            "--data-weight",
            "0.5",
            "--epochs",
            "1",
            "--batch-size",
            "2",
            "--val-every",
            "0",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    meta = torch.load(out / "last.pt", map_location="cpu", weights_only=False)["metadata"]
    assert len(meta["data"]["roots"]) == 2


def test_joint_training_with_scene_labels_ignores_outside_the_camera_view(
    real_format_roots, tmp_path
):
    from model import build_model
    from model.training.referent_step import detection_targets, in_grid_actors
    from scenes.talk2radar.scene_labels import SceneLabels

    t2r, vod = real_format_roots
    frames = FrameDataset(t2r, "train", scene_labels=SceneLabels(vod))
    item = frames[0]
    assert item.region is not None and item.from_labels and item.given
    model = build_model("small")
    targets = detection_targets(model, [item], [in_grid_actors(item.actors, model)])
    assert targets.ignore is not None
    ignored = targets.ignore[0, 0]
    assert ignored.any() and not ignored.all()
    # The cells beside the ego, outside the camera's view, are ignored; straight ahead is not.
    grid = model.head_grid
    col, row = (int(v) for v in grid.xy_to_cell(np.array([[2.0, 20.0]]))[0])
    assert bool(ignored[row, col])
    col, row = (int(v) for v in grid.xy_to_cell(np.array([[20.0, 0.0]]))[0])
    assert not bool(ignored[row, col])

    out = tmp_path / "run"
    code = main(
        [
            "--data",
            str(t2r),
            "--scene-labels",
            str(vod),
            "--epochs",
            "1",
            "--batch-size",
            "2",
            "--val-every",
            "0",
            "--out",
            str(out),
        ]
    )
    assert code == 0 and (out / "last.pt").is_file()


def test_a_finished_run_is_calibrated_on_the_validation_split(monkeypatch, tmp_path, capsys):
    import model.training.calibrate as calibrate_module
    from model.training.calibrate import Calibration

    seen = {}

    def fake(model, data, split="val", limit=0, min_prompts=50, talk2car=None):
        seen["split"] = split
        return Calibration(0.35, 80.0, 60.0, 120, ())

    monkeypatch.setattr(calibrate_module, "calibrate", fake)
    release = tmp_path / "release"
    generate_root(release, 4, SynthSettings(seed=9), split_fractions=(0.5, 0.5, 0.0))
    shutil.rmtree(meta_dir(release))
    out = tmp_path / "run"
    args = ["--data", str(release), "--freeze-scene", "--init-detector"]
    args += ["checkpoints/tpcnet-small.pt", "--epochs", "1", "--val-every", "0", "--out", str(out)]
    assert main(args) == 0
    assert seen == {"split": "val"}
    assert "operating threshold 0.350" in capsys.readouterr().out
    meta = load_checkpoint(out / "last.pt").checkpoint_metadata
    assert meta.operating_threshold == 0.35
    assert meta.operating_threshold_source["split"] == "val"
    # A resume of the finished run still loads (the state and last.pt agree on the step).
    assert main([*args, "--resume"]) == 0
