"""The bundled nuScenes-class checkpoint's making (issue 36, item 3): training on a
``--classes nuscenes`` world generates prompts over its road users; a nuScenes root's categories
map onto the model's set; ``--init-other-classes`` starts a ten-class model from the three-class
checkpoint (class-shaped weights remapped by class name, recorded in the lineage); the evaluator
reports the prompts whose referents are all beyond Car / Pedestrian / Cyclist."""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from model.checkpoint import DEFAULT_CHECKPOINT, load_checkpoint, read_checkpoint
from model.evaluation.grounding import (
    PromptBoxes,
    format_grounding_tables,
    grounding_metrics,
    prompt_outcome,
)
from model.referent.candidates import class_columns, geometry_feature_width
from model.referent.context import relation_columns
from model.training.class_remap import geometry_input_keys, init_other_classes
from model.training.config import TrainConfig, TrainingError
from model.training.loop import train
from model.training.referent_step import frame_prompts
from model.training.start import start_model
from scenes.datasets.frames import FrameDataset
from scenes.geometry.classes import NUSCENES, VOD
from scenes.language.prompts.sampling import PromptConfig
from scenes.synth.generate import SynthSettings, generate_root

BEYOND = set(NUSCENES.names) - set(VOD.names)
"""The nuscenes classes beyond the vod three (Bicycle included: nuScenes has no Cyclist)."""


@pytest.fixture(scope="module")
def road_users(tmp_path_factory) -> Path:
    """A small ``--classes nuscenes`` world (4 worlds, 2 train), no camera (about 3 s)."""
    root = tmp_path_factory.mktemp("nusc") / "root"
    settings = SynthSettings(seed=5, classes="nuscenes", camera=None)
    generate_root(root, 8, settings, split_fractions=(0.5, 0.25, 0.25))
    return root


def _referent_classes(frame, prompts) -> Counter:
    cls = {a.actor_id: a.cls for a in frame.actors}
    return Counter(frozenset(cls[r] for r in refs) for _, refs in prompts)


def test_training_prompts_follow_the_worlds_class_set(road_users):
    """The run's prompt settings (``TrainConfig.prompt_draw``: no class set of their own) draw a
    nuscenes world's frames over its own set (class-balanced anchors, its own out-of-class
    nouns): the rare large vehicles are talked about more, and the many parked bicycles less,
    than the same draws over the vod set (what training did before)."""
    frames = FrameDataset(road_users, "train", classes=NUSCENES)
    config = PromptConfig()
    about, before = Counter(), Counter()
    for i in range(len(frames)):
        frame = frames[i]
        assert frame.prompt_classes == "nuscenes"
        prompts = frame_prompts(frame, np.random.default_rng(i), 60, config)
        old = replace(frame, prompt_classes="vod")
        old_prompts = frame_prompts(old, np.random.default_rng(i), 60, config)
        for counts, drawn in ((about, prompts), (before, old_prompts)):
            for classes, n in _referent_classes(frame, drawn).items():
                if len(classes) == 1 and classes <= BEYOND:
                    counts[next(iter(classes))] += n
    large = ("Truck", "Bus", "Trailer", "ConstructionVehicle")
    assert len(about) >= 5, about  # single-class prompts about at least five road users
    assert sum(about[c] for c in large) > 1.5 * sum(before[c] for c in large), (about, before)
    assert about["Bicycle"] < before["Bicycle"] / 2, (about, before)
    # a vod world's frames stay vod
    vod_root = road_users.parent / "vod"
    generate_root(vod_root, 2, SynthSettings(seed=5, camera=None), split_fractions=(1, 0, 0))
    assert FrameDataset(vod_root, "train", classes=NUSCENES)[0].prompt_classes == "vod"


def test_nuscenes_root_categories_map_onto_the_models_set(nuscenes_training_root):
    """A nuScenes root's samples as training frames: a nuscenes model's actors hold the added
    vehicle.truck (a Truck, no ignored box), a vod model ignores it; prompts follow the set."""
    from model.training.data import RootSpec, frame_dataset

    spec = RootSpec(
        str(nuscenes_training_root), 1.0, None, str(nuscenes_training_root / "commands")
    )
    nus = frame_dataset(spec, "train", NUSCENES)
    vod = frame_dataset(spec, "train", VOD)
    a, b = nus.item(0), vod.item(0)
    assert Counter(x.cls for x in a.actors)["Truck"] == 1 and len(a.ignore_boxes) == 0
    assert "Truck" not in {x.cls for x in b.actors} and len(b.ignore_boxes) == 1
    assert (a.prompt_classes, b.prompt_classes) == ("nuscenes", "vod")
    assert nus.command_count == vod.command_count  # the commands refer to classes of both


def test_geometry_input_keys_follow_the_stages_layout():
    """Each class's one-hot column and relation block where the stage's feature code puts them."""
    cfg = load_checkpoint(DEFAULT_CHECKPOINT).cfg.referent
    for classes in (VOD, NUSCENES):
        keys = geometry_input_keys(cfg, classes)
        for name, column in zip(classes.names, class_columns(len(classes)), strict=True):
            assert keys[column] == ("class", name)
            block = relation_columns(name, "nearest", classes)
            start = geometry_feature_width(len(classes)) + block.start
            assert keys[start] == ("relation", name, "0")
        assert len(set(keys)) == len(keys)


def test_init_other_classes_remaps_by_class_name(untrained_model):
    payload = read_checkpoint(DEFAULT_CHECKPOINT)
    state = payload["state_dict"]
    model = untrained_model("referent", classes="nuscenes")
    fresh = {k: v.clone() for k, v in model.state_dict().items()}
    done = init_other_classes(model, payload, "tpcnet-small.pt")
    own = model.state_dict()
    assert done.shared == ("Car", "Pedestrian") and done.reinitialised == ()
    assert set(done.remapped) == {
        "head.heatmap.1.weight",
        "head.heatmap.1.bias",
        "referent.geometry.0.weight",
        "referent.geometry_gate.weight",
        "referent.geometry_gate.bias",
    }
    for name, value in own.items():
        if name not in done.remapped:
            assert torch.equal(value, state[name]), name
    heat, old_heat = own["head.heatmap.1.bias"], state["head.heatmap.1.bias"]
    assert heat[NUSCENES.index("Pedestrian")] == old_heat[VOD.index("Pedestrian")]
    assert heat[NUSCENES.index("Truck")] == fresh["head.heatmap.1.bias"][NUSCENES.index("Truck")]
    cfg = model.cfg.referent
    new_keys, old_keys = geometry_input_keys(cfg, NUSCENES), geometry_input_keys(cfg, VOD)
    w, old_w = own["referent.geometry.0.weight"], state["referent.geometry.0.weight"]
    for key in (("class", "Car"), ("relation", "Pedestrian", "3"), ("compare", "5"), ("rank", "0")):
        assert torch.equal(w[:, new_keys.index(key)], old_w[:, old_keys.index(key)]), key
    for key in (("class", "Truck"), ("relation", "Bus", "0"), ("picked", "TrafficCone", "2")):
        assert not w[:, new_keys.index(key)].any(), key
    # the Cyclist's columns have no home in the nuscenes set
    assert ("class", "Cyclist") not in new_keys
    assert any("re-initialised" in x or "new" in x for x in done.lines())


def _cfg(root: Path, out: Path, **kw) -> TrainConfig:
    base = dict(
        data=str(root), out=str(out), epochs=1, batch_size=2, val_every=0, warmup_steps=0,
        log_every=1, max_steps=1, calibrate=False, device="cpu", prompts_per_scene=2,
        classes="nuscenes",
    )  # fmt: skip
    base.update(kw)
    return TrainConfig(**base)


def test_init_other_classes_trains_and_is_recorded_in_the_lineage(road_users, tmp_path):
    """A one-step run from the vod checkpoint records the remapping; a run started from it with
    ``--init`` carries it on; ``--init`` of the vod checkpoint stays refused in one line."""
    with pytest.raises(TrainingError, match=r"^give one of --init, .* not --init and --init-other"):
        _cfg(road_users, tmp_path / "x", init="a.pt", init_other_classes="b.pt")
    with pytest.raises(TrainingError, match="--init-other-classes") as err:
        start_model(
            _cfg(road_users, tmp_path / "y", init=str(DEFAULT_CHECKPOINT)),
            False, 0, 1, torch.device("cpu"),
        )  # fmt: skip
    assert "\n" not in str(err.value)
    first = tmp_path / "first"
    train(_cfg(road_users, first, init_other_classes=str(DEFAULT_CHECKPOINT)))
    record = load_checkpoint(first / "last.pt").checkpoint_metadata.class_remap
    assert record["from_classes"] == "vod" and record["to_classes"] == "nuscenes"
    assert record["shared"] == ["Car", "Pedestrian"] and "head.heatmap.1.bias" in record["remapped"]
    model, _, _ = start_model(
        _cfg(road_users, tmp_path / "second", init=str(first / "last.pt")),
        False, 0, 1, torch.device("cpu"),
    )  # fmt: skip
    assert model.checkpoint_metadata.class_remap == record


def _outcome(classes: list[str], hit: bool):
    boxes = np.tile(np.array([[10.0, 0.0, -1.0, 4.0, 2.0, 1.6, 0.0]]), (len(classes), 1))
    boxes[:, 1] = np.arange(len(classes)) * 5.0
    referents = PromptBoxes.make(boxes, classes)
    predicted = PromptBoxes.make(boxes[:1] + (0 if hit else 20.0), classes[:1], np.array([0.9]))
    return prompt_outcome("0", ("class",), predicted, referents, 0.5)


def test_prompts_grouped_by_their_referents_classes():
    outcomes = [
        _outcome(["Truck"], True),
        _outcome(["Bus", "TrafficCone"], False),
        _outcome(["Car"], True),
        _outcome(["Car", "Truck"], True),
    ]
    groups = ["beyond_vod", "beyond_vod", "vod_classes", None]
    assert [o.class_group() for o in outcomes] == groups
    metrics = grounding_metrics(outcomes, 0.5)
    assert metrics.by_group["beyond_vod"].prompts == 2
    assert metrics.by_group["beyond_vod"].acc_25 == pytest.approx(50.0)
    assert metrics.by_group["vod_classes"].acc_25 == pytest.approx(100.0)
    table = format_grounding_tables({"model": (metrics, None)})
    assert "beyond_vod" in table and "vod_classes" in table
    # a vod evaluation, whose referents are all of the three, has no class groups (as before)
    vod_only = format_grounding_tables({"model": (grounding_metrics(outcomes[2:3], 0.5), None)})
    assert "beyond_vod" not in vod_only and "vod_classes" not in vod_only


def test_app_serves_the_roots_bundled_checkpoint(road_users, nuscenes_root, tmp_path, monkeypatch):
    """``python launch.py`` without ``--checkpoint``: the nuscenes checkpoint on a nuScenes root
    and on a ``--classes nuscenes`` root, the vod one elsewhere; ``--checkpoint`` still wins."""
    import launch
    from model.checkpoint import BUNDLED

    vod_root = tmp_path / "vod"
    generate_root(vod_root, 2, SynthSettings(seed=5, camera=None), split_fractions=(1, 0, 0))
    assert launch.root_classes(road_users) == "nuscenes"
    assert launch.root_classes(nuscenes_root) == "nuscenes"
    assert launch.root_classes(vod_root) == "vod"
    assert launch.root_classes(tmp_path) == "vod"  # no manifest: a release
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "synth_manifest.jsonl").write_text("{}\n")
    with pytest.raises(launch.LaunchError, match=r"synth_manifest.jsonl:1: not the generator"):
        launch.root_classes(broken)
    # which file is read: a stand-in for each bundled checkpoint (the small vod one)
    read = []
    monkeypatch.setattr("model.load_checkpoint", lambda path, device: read.append(path) or path)
    stand_in = tmp_path / "nusc.pt"
    stand_in.write_bytes(b"")
    monkeypatch.setitem(BUNDLED, "nuscenes", stand_in)
    assert launch.load_model(None, "cpu", classes="nuscenes") == (stand_in, None)
    assert launch.load_model(None, "cpu", classes="vod") == (DEFAULT_CHECKPOINT, None)
    assert launch.load_model(tmp_path / "x.pt", "cpu", classes="nuscenes")[0] == tmp_path / "x.pt"
    stand_in.unlink()  # not bundled (yet): the vod one, with a warning
    assert launch.load_model(None, "cpu", classes="nuscenes") == (DEFAULT_CHECKPOINT, None)
