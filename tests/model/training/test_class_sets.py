"""Class sets as configuration (issue 36, items 1 and 4): a ``nuscenes`` (10-class) model builds,
trains from scratch, decodes 10-class boxes, saves and reloads with its set; a checkpoint of
another set is refused in one line; readers, the evaluator's tables, the class prompts and the
answer words follow the set; checkpoints stored before the field existed read as ``vod``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from model.checkpoint import DEFAULT_CHECKPOINT, load_checkpoint, read_checkpoint, write_payload
from model.config import HeadConfig
from model.core.grid import BevGrid
from model.core.labelled import LabelledBoxes
from model.evaluation.baselines import class_noun_prompt
from model.evaluation.class_prompt_counts import CLASS_PROMPTS, class_prompts
from model.evaluation.metrics import evaluate_frames
from model.head.decode import decode
from model.head.detector import HeadOutput
from model.head.targets import collate_targets, draw_targets
from model.training.config import TrainConfig, TrainingError
from model.training.loop import train
from model.training.start import start_model
from scenes.frame.kitti import boxes_to_labels, labels_to_boxes, outside_class_counts
from scenes.geometry.calib import IMAGE_SIZE
from scenes.geometry.classes import NUSCENES, VOD, class_set
from scenes.synth.generate import SynthSettings, generate_root
from tests.vod_fixtures import vod_lidar_calibration

GRID = BevGrid(x_min=0.0, x_max=51.2, y_min=-25.6, y_max=25.6, cell=0.64)


def test_presets_map_label_names_and_categories_onto_their_classes():
    assert VOD.names == ("Car", "Pedestrian", "Cyclist") and len(NUSCENES) == 10
    assert class_set("nuscenes") is NUSCENES
    with pytest.raises(ValueError, match="unknown class set 'kitti'"):
        class_set("kitti")
    # VoD's own names: Cyclist is a VoD class; nuScenes counts rider and bicycle as a bicycle
    assert [VOD.label_class(n) for n in ("car", "Cyclist", "truck", "motor")] == [
        "Car",
        "Cyclist",
        None,
        None,
    ]
    assert [NUSCENES.label_class(n) for n in ("car", "Cyclist", "truck", "motor", "rider")] == [
        "Car",
        "Bicycle",
        "Truck",
        "Motorcycle",
        None,
    ]
    # nuScenes' own detection mapping; the VoD Cyclist needs a rider
    assert NUSCENES.category_class("vehicle.bus.bendy") == "Bus"
    assert NUSCENES.category_class("vehicle.bicycle") == "Bicycle"
    assert VOD.category_class("vehicle.bicycle") is None
    assert VOD.category_class("vehicle.bicycle", ("cycle.with_rider",)) == "Cyclist"
    assert NUSCENES.category_class("movable_object.debris") is None
    # item 4: the empty answer's words come from the set's plurals
    assert VOD.plural_list() == "cars, pedestrians and cyclists"
    assert NUSCENES.plural_list().endswith("traffic cones and barriers")


def _label_lines(names: list[str]) -> list:
    calib = vod_lidar_calibration()
    boxes = np.array([[8.0 + 4 * i, 0.0, -1.0, 2.0, 1.0, 1.5, 0.3] for i in range(len(names))])
    return boxes_to_labels(boxes, names, calib, image_size=IMAGE_SIZE)


def test_reader_maps_vod_names_per_set_and_counts_the_others():
    labels = _label_lines(["Car", "truck", "motor", "rider", "Cyclist", "DontCare"])
    calib = vod_lidar_calibration()
    boxes, names = labels_to_boxes(labels, calib)
    assert names == ("Car", "Cyclist") and boxes.shape == (2, 7)
    assert outside_class_counts(labels) == {"motor": 1, "rider": 1, "truck": 1}
    boxes, names = labels_to_boxes(labels, calib, NUSCENES)
    assert names == ("Car", "Truck", "Motorcycle", "Bicycle")
    assert outside_class_counts(labels, NUSCENES) == {"rider": 1}


def _perfect_output(boxes: np.ndarray, names: list[str], cfg: HeadConfig) -> HeadOutput:
    """Logit +10 at each anchor cell in its class's channel, the regression targets there."""
    t = collate_targets([draw_targets(boxes, names, GRID, cfg)])
    n, (h, w) = len(cfg.class_set), GRID.shape
    heatmap = torch.full((1, n, h * w), -10.0)
    regression = torch.zeros((1, 8, h * w))
    for k in torch.nonzero(t.mask[0]).flatten().tolist():
        idx = int(t.indices[0, k])
        heatmap[0, int(t.labels[0, k]), idx] = 10.0
        regression[0, :, idx] = t.regression[0, k]
    return HeadOutput(heatmap.reshape(1, n, h, w), regression.reshape(1, 8, h, w))


def test_ten_channel_targets_decode_to_ten_class_boxes():
    cfg = HeadConfig(classes="nuscenes")
    names = ["Truck", "TrafficCone", "Bus", "Car"]
    boxes = np.array(
        [
            [20.0, 5.0, -0.3, 6.9, 2.5, 2.8, 0.4],
            [10.0, -3.0, -1.2, 0.4, 0.4, 1.0, 0.7],  # a cone: no heading
            [35.0, -8.0, 0.0, 10.5, 2.9, 3.4, -0.2],
            [15.0, 10.0, -0.9, 4.5, 1.9, 1.6, 1.0],
        ]
    )
    targets = draw_targets(boxes, names, GRID, cfg)
    assert targets.heatmap.shape == (10, *GRID.shape)
    assert targets.labels.tolist() == [1, 8, 2, 0]
    assert targets.regression[1, 6:].tolist() == [0.0, 1.0]  # the cone's yaw target is 0
    (det,) = decode(_perfect_output(boxes, names, cfg), GRID, cfg)
    order = np.argsort([names.index(c) for c in det.classes])
    assert [det.classes[i] for i in order] == names
    want = boxes.copy()
    want[1, 6] = 0.0
    np.testing.assert_allclose(det.boxes[order], want, atol=1e-4)
    # the vod head has three channels: a 10-channel map is refused, naming the set
    with pytest.raises(ValueError, match=r"\(B, 3, H, W\) for the 'vod' class set"):
        decode(_perfect_output(boxes, names, cfg), GRID, HeadConfig())


@pytest.fixture(scope="module")
def vod_world(tmp_path_factory) -> Path:
    """A small synthetic root of today's world (cars, pedestrians, cyclists)."""
    root = tmp_path_factory.mktemp("world") / "root"
    generate_root(root, 4, SynthSettings(seed=3), split_fractions=(0.5, 0.25, 0.25))
    return root


@pytest.fixture(scope="module")
def truck_root(vod_world, tmp_path_factory) -> Path:
    """``vod_world`` with its cars relabelled trucks (sidecar actors and label_2): what a
    nuscenes model can train on before the world draws trucks of its own."""
    root = tmp_path_factory.mktemp("trucks") / "root"
    shutil.copytree(vod_world, root)
    for meta in (root / "meta").glob("*.json"):
        data = json.loads(meta.read_text())
        for actor in data["actors"]:
            if actor["cls"] == "Car":
                actor["cls"] = "Truck"
        meta.write_text(json.dumps(data))
    for label in (root / "lidar" / "training" / "label_2").glob("*.txt"):
        lines = label.read_text().splitlines()
        label.write_text(
            "".join(f"Truck{x[3:]}\n" if x.startswith("Car ") else x + "\n" for x in lines)
        )
    return root


def _cfg(root: Path, out: Path, **kw) -> TrainConfig:
    base = dict(
        data=str(root),
        out=str(out),
        epochs=5,
        batch_size=2,
        val_every=0,
        warmup_steps=0,
        log_every=1,
        max_steps=2,
        calibrate=False,
        device="cpu",
        prompts_per_scene=2,
    )
    base.update(kw)
    return TrainConfig(**base)


def test_nuscenes_referent_model_trains_from_scratch(vod_world, tmp_path):
    """The referent path (detector targets, candidates, the stage's 10-class evidence) on the
    world's cars and pedestrians (its cyclists are no nuscenes class: no targets, no candidates;
    a prompt about them is left out). Trucks in the generated prompts wait for the world and the
    prompts of item 2."""
    out = tmp_path / "ref"
    assert train(_cfg(vod_world, out, classes="nuscenes")).step == 2
    model = load_checkpoint(out / "last.pt")
    assert model.cfg.class_set is NUSCENES and model.cfg.grounding == "referent"
    assert model.grounding.stage.num_classes == 10


def test_nuscenes_model_trains_from_scratch_saves_and_reloads(truck_root, tmp_path):
    """The paper's path on label_2 trucks (targets of the Truck channel)."""
    out = tmp_path / "run"
    state = train(_cfg(truck_root, out, classes="nuscenes", grounding="tpcnet", lr=2e-3))
    assert state.step == 2
    model = load_checkpoint(out / "last.pt")
    assert model.cfg.class_set is NUSCENES
    losses = [json.loads(x) for x in (out / "log.jsonl").read_text().splitlines()]
    assert all(np.isfinite(x["loss"]) for x in losses if "loss" in x)
    assert read_checkpoint(out / "last.pt")["config"]["head"]["classes"] == "nuscenes"
    assert model.scene.head.heatmap[-1].out_channels == 10
    rng = np.random.default_rng(0)
    lidar = np.c_[rng.uniform([2, -20, -1.7], [50, 20, 1], (3000, 3)), rng.uniform(0, 1, 3000)]
    feats = model.encode_scene(lidar.astype(np.float32), np.zeros((0, 7), np.float32))
    answer = model.ground(feats, "the truck", score_threshold=0.0)
    assert len(answer.classes) and set(answer.classes) <= set(NUSCENES.names)
    assert answer.heatmaps.shape[0] == 10
    # the same root read as vod has no label of its classes left in the relabelled frames
    # (trucks are not vod targets); a nuscenes checkpoint cannot start a vod run
    with pytest.raises(
        TrainingError,
        match=r"^\S+last.pt: a checkpoint of the 'nuscenes' class set cannot start a 'vod' model",
    ) as err:
        start_model(
            _cfg(truck_root, tmp_path / "b", init=str(out / "last.pt")),
            False,
            0,
            1,
            torch.device("cpu"),
        )
    assert "\n" not in str(err.value)


def test_labelled_candidates_of_the_models_set_only(untrained_model):
    model = untrained_model("referent", classes="nuscenes", operating_threshold=0.0)
    rng = np.random.default_rng(0)
    lidar = np.c_[rng.uniform([2, -20, -1.7], [50, 20, 1], (3000, 3)), rng.uniform(0, 1, 3000)]
    lidar = lidar.astype(np.float32)
    truck = np.array([[12.0, 1.0, -0.5, 6.9, 2.5, 2.8, 0.0]])
    radar = np.zeros((0, 7), np.float32)
    feats = model.encode_scene(lidar, radar, candidates=LabelledBoxes(truck, [1], NUSCENES))
    answer = model.ground(feats, "the truck", score_threshold=0.0)
    assert answer.classes == ("Truck",)
    with pytest.raises(ValueError, match="'vod' class set given to a model of the 'nuscenes'"):
        model.encode_scene(lidar, radar, candidates=LabelledBoxes(truck, [0]))


def test_vod_checkpoint_refused_by_a_nuscenes_run_and_loads_as_vod(truck_root, tmp_path):
    payload = read_checkpoint(DEFAULT_CHECKPOINT)
    payload["config"]["head"].pop("classes", None)  # as stored before the field existed
    assert load_checkpoint(write_payload(tmp_path / "old.pt", payload)).cfg.class_set is VOD
    assert load_checkpoint(DEFAULT_CHECKPOINT).cfg.class_set is VOD
    cfg = _cfg(
        truck_root, tmp_path / "c", classes="nuscenes", init_detector=str(DEFAULT_CHECKPOINT)
    )
    with pytest.raises(
        TrainingError, match="a checkpoint of the 'vod' class set cannot start a 'nuscenes' model"
    ) as err:
        start_model(cfg, False, 0, 1, torch.device("cpu"))
    assert "\n" not in str(err.value)
    with pytest.raises(TrainingError, match="--classes must be one of"):
        _cfg(truck_root, tmp_path / "d", classes="kitti")


def test_evaluator_tables_have_a_row_per_class_of_the_set():
    calib = vod_lidar_calibration()
    boxes = np.array([[10.0, 0.0, -0.3, 6.9, 2.5, 2.8, 0.0], [20.0, 4.0, -1.0, 2.0, 0.8, 1.5, 0.0]])
    gt = boxes_to_labels(boxes, ["truck", "motor"], calib)  # VoD's spelling
    dt = boxes_to_labels(boxes, ["Truck", "Motorcycle"], calib, scores=np.array([0.9, 0.8]))
    result = evaluate_frames({"0": gt}, {"0": dt}, classes=NUSCENES)
    rows = {c.name: c for c in result.entire_area.classes}
    assert tuple(rows) == NUSCENES.names
    assert rows["Truck"].num_gt == rows["Motorcycle"].num_gt == 1  # VoD's names mapped
    assert rows["Truck"].ap_3d.r11 > 0 and rows["Motorcycle"].ap_3d.r11 > 0
    wrong = boxes_to_labels(boxes, ["Bus", "Bicycle"], calib, scores=np.array([0.9, 0.8]))
    missed = {
        c.name: c
        for c in evaluate_frames({"0": gt}, {"0": wrong}, classes=NUSCENES).entire_area.classes
    }
    assert missed["Truck"].ap_3d.r11 == 0 and missed["Motorcycle"].ap_3d.r11 == 0
    vod = evaluate_frames({"0": gt}, {"0": dt})
    assert tuple(c.name for c in vod.entire_area.classes) == VOD.names
    assert vod.unknown_dt_classes == {"Motorcycle": 1}  # a vod evaluation does not know it


def test_class_prompts_and_nouns_follow_the_set():
    assert CLASS_PROMPTS == {
        "Cyclist": "the cyclists",
        "Pedestrian": "the pedestrians",
        "Car": "the cars",
    }
    prompts = class_prompts(NUSCENES)
    assert len(prompts) == 10 and prompts["ConstructionVehicle"] == "the construction vehicles"
    assert class_noun_prompt("TrafficCone") == "the traffic cones"
    assert class_noun_prompt(None) == "the objects"
    with pytest.raises(ValueError, match="no class noun for 'Tram'"):
        class_noun_prompt("Tram")


@pytest.mark.slow
def test_nuscenes_model_trains_under_torchrun(truck_root, tmp_path, torchrun):
    out = tmp_path / "ddp"
    args = ["-m", "model.train", "--classes", "nuscenes", "--grounding", "tpcnet"]
    args += ["--data", str(truck_root), "--out", str(out), "--max-steps", "2"]
    args += ["--batch-size", "1", "--val-every", "0", "--device", "cpu"]
    log = tmp_path / "torchrun.log"
    code = torchrun(args, log, timeout=300)
    assert code == 0, log.read_text()[-3000:]
    model = load_checkpoint(out / "last.pt")
    assert model.checkpoint_metadata.step == 2 and model.cfg.class_set is NUSCENES


def test_nuscenes_categories_map_onto_the_served_set(nuscenes_training_root):
    """A nuScenes root's annotations (a parked vehicle.truck added to every sample) as the app
    reads them: with ``vod`` the truck is outside the set; with ``nuscenes`` it is a Truck and a
    ridden bicycle a Bicycle (nuScenes' mapping), not a Cyclist."""
    from collections import Counter

    from scenes.datasets.source import NuScenesSource

    root = nuscenes_training_root
    vod = NuScenesSource(root, root / "commands")
    nus = NuScenesSource(root, root / "commands", NUSCENES)
    for sid in list(vod.nuscenes.samples)[:2]:
        a, b = Counter(vod.load(sid).classes), Counter(nus.load(sid).classes)
        assert a["Truck"] == 0 and b["Truck"] == 1
        assert b["Bicycle"] == a["Cyclist"] and b["Car"] == a["Car"]
        assert b["Pedestrian"] == a["Pedestrian"]
