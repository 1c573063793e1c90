"""scenes.nuscenes: the export of a tiny synthetic root read back (frames equal the source,
commands with the same boxes), strict errors on malformed files, skip reasons by count, an
empty radar sweep, the class mapping."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from scenes.nuscenes.classes import model_class
from scenes.nuscenes.root import NuScenesRoot
from scenes.nuscenes.sensorfiles import (
    SensorFileError,
    empty_radar,
    radar_dtype,
    read_lidar,
    read_radar,
    write_radar,
)
from scenes.nuscenes.tables import NuScenesError
from scenes.nuscenes.talk2car import (
    CommandFileError,
    camera_box_to_model,
    model_box_to_camera,
    read_commands,
)
from scenes.nuscenes.writer import token as make_token
from scenes.talk2radar.root import Talk2RadarRoot


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny synthetic root with enough single-referent prompts (4 worlds of 4 prompts)."""
    from scenes.synth.camera import CameraConfig
    from scenes.synth.generate import SynthSettings, generate_root

    out = tmp_path_factory.mktemp("nusc-source") / "synth"
    settings = SynthSettings(seed=5, prompts_per_world=4, camera=CameraConfig(image_scale=0.125))
    generate_root(out, 16, settings, split_fractions=(0.5, 0.25, 0.25))
    return out


@pytest.fixture(scope="module")
def exported(source: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    from scenes.export_nuscenes import export

    out = tmp_path_factory.mktemp("nusc") / "nusc"
    export(source, out, seed=3)
    # every command in one file too, so the edits below have several to work on
    commands = [
        c
        for split in ("train", "val", "test")
        for c in json.loads((out / "commands" / f"{split}_commands.json").read_text())["commands"]
    ]
    (out / "all").mkdir()
    (out / "all" / "all_commands.json").write_text(
        json.dumps({"scene_tokens": [], "commands": commands})
    )
    return out


def _paired(ours: np.ndarray, source: np.ndarray) -> np.ndarray:
    """``source``'s rows in the order of their nearest row of ``ours`` (xyz and scan): one to one."""
    from scipy.spatial import cKDTree

    assert len(ours) == len(source)
    _, index = cKDTree(np.c_[source[:, :3], 100 * source[:, 6]]).query(
        np.c_[ours[:, :3], 100 * ours[:, 6]]
    )
    assert len(set(index.tolist())) == len(index)
    return source[index]


def test_round_trip_frames_equal_the_source(source: Path, exported: Path) -> None:
    src = Talk2RadarRoot(source)
    root = NuScenesRoot(exported, radar_sweeps=5)
    assert root.version == "v1.0-trainval"
    first: dict = {}
    for split in ("train", "val", "test"):
        for sid in src.ids(split):
            first.setdefault(src.frame_key(sid), sid)
    assert len(root.samples) == len(first)
    for token, sid in zip(root.samples, first.values(), strict=True):
        frame, sample, meta = root.frame(token), src.load(sid), src.load_meta(sid)
        np.testing.assert_allclose(frame.lidar, sample.lidar, atol=1e-4)
        assert np.all(frame.lidar_time == 0)
        np.testing.assert_allclose(frame.radar, _paired(frame.radar, sample.radar), atol=1e-4)
        np.testing.assert_allclose(frame.boxes, [a.box for a in meta.actors], atol=1e-4)
        assert frame.image_size == (1600, 900) and frame.image_path is not None
        assert root.sample_of_camera(frame.cam_front_token) == token
        # the camera sees the boxes where the source camera does (same extrinsics)
        np.testing.assert_allclose(
            frame.to_camera[:3, :3], sample.calib.velo_to_cam[:3, :3], atol=1e-9
        )


def test_single_sweep_keeps_the_newest_scan(exported: Path) -> None:
    root = NuScenesRoot(exported, radar_sweeps=1)
    frame = root.frame(root.samples[0])
    assert len(frame.radar) and np.all(frame.radar[:, 6] == 0)
    assert np.all((frame.radar_time > 0) & (frame.radar_time < 0.05))


def test_commands_read_back_with_the_same_boxes(source: Path, exported: Path) -> None:
    src = Talk2RadarRoot(source)
    root = NuScenesRoot(exported)
    total = 0
    for split in ("train", "val", "test"):
        cs = read_commands(exported / "commands", split, root)
        assert not cs.skipped
        for c in cs.commands:
            ref = cs.referent[c.command_token]
            frame_boxes, _, _ = root.annotation_boxes(c.sample_token)
            np.testing.assert_allclose(ref.box, frame_boxes[ref.index], atol=1e-9)
            np.testing.assert_allclose(
                camera_box_to_model(root.to_camera(c.sample_token), *c.box_camera),
                ref.box,
                atol=1e-4,
            )
            sid = next(s for s in src.ids(split) if make_token("command", s) == c.command_token)
            meta = src.load_meta(sid)
            actor = next(a for a in meta.actors if a.actor_id == meta.referent_ids[0])
            np.testing.assert_allclose(ref.box, actor.box, atol=1e-4)
            assert ref.cls == actor.cls
            total += 1
    assert total > 0


def test_commands_are_phrased_as_commands(source: Path, exported: Path, tmp_path: Path) -> None:
    """Item 5: each command is its single-referent prompt wrapped into a driving instruction
    (the prompt's noun phrase inside, the sentence not the prompt), the same for the same seed;
    ``phrasing=None`` keeps the prompts as written."""
    from scenes.export_nuscenes import export
    from scenes.language.prompts.commands import noun_phrase_of

    src = Talk2RadarRoot(source)
    prompts = {make_token("command", s): src.load_prompt(s) for sp in ("train", "val", "test")
               for s in src.ids(sp)}  # fmt: skip

    def sentences(root: Path) -> dict[str, str]:
        return {
            c["command_token"]: c["command"]
            for split in ("train", "val", "test")
            for c in json.loads((root / "commands" / f"{split}_commands.json").read_text())[
                "commands"
            ]
        }

    ours = sentences(exported)
    assert ours
    for command_token, text in ours.items():
        prompt = prompts[command_token]
        assert text != prompt
        assert noun_phrase_of(prompt).lower() in text.lower()
    export(source, tmp_path / "again", seed=3)
    assert sentences(tmp_path / "again") == ours
    export(source, tmp_path / "plain", seed=3, phrasing=None)
    assert sentences(tmp_path / "plain") == {t: prompts[t] for t in ours}
    with pytest.raises(ValueError, match="phrasing"):
        export(source, tmp_path / "bad", seed=3, phrasing="poetic")


def test_box_conversions_are_inverse() -> None:
    rng = np.random.default_rng(0)
    to_camera = np.eye(4)
    to_camera[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]
    to_camera[:3, 3] = [0.1, 0.5, -0.3]
    for _ in range(20):
        box = np.r_[rng.uniform(-30, 30, 3), rng.uniform(0.5, 5, 3), rng.uniform(-np.pi, np.pi)]
        back = camera_box_to_model(to_camera, *model_box_to_camera(to_camera, box))
        np.testing.assert_allclose(back, box, atol=1e-9)


def _edit(path: Path, change) -> None:
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


def test_skip_reasons_are_counted(exported: Path, tmp_path: Path) -> None:
    root = NuScenesRoot(exported)
    src = exported / "all" / "all_commands.json"
    n = len(json.loads(src.read_text())["commands"])
    assert n >= 3
    folder = tmp_path / "cmds"
    folder.mkdir()
    target = folder / "all_commands.json"
    shutil.copy(src, target)

    def change(data: dict) -> None:
        cmds = data["commands"]
        cmds[0]["box_token"] = "0" * 32
        cmds[1]["sample_token"] = root.samples[0]  # a sample token, not a CAM_FRONT one
        cmds[2]["translation"][0] += 1.0

    _edit(target, change)
    cs = read_commands(folder, "all", root)
    assert cs.skipped["box_token not in sample_annotation"] == 1
    assert cs.skipped["sample_token is not a CAM_FRONT sample_data"] == 1
    assert cs.skipped["camera-frame box disagrees with box_token's annotation"] == 1
    assert len(cs.commands) == n - 3


def test_category_outside_the_class_set_is_counted(exported: Path, tmp_path: Path) -> None:
    root_dir = tmp_path / "nusc"
    shutil.copytree(exported, root_dir)
    cmd = json.loads((root_dir / "all" / "all_commands.json").read_text())["commands"][0]
    ann_file = root_dir / "v1.0-trainval" / "sample_annotation.json"
    anns = json.loads(ann_file.read_text())
    instance = next(a for a in anns if a["token"] == cmd["box_token"])["instance_token"]
    inst_file = root_dir / "v1.0-trainval" / "instance.json"
    cats = {
        c["name"]: c["token"]
        for c in json.loads((root_dir / "v1.0-trainval" / "category.json").read_text())
    }
    _edit(
        inst_file,
        lambda d: [
            i.update(category_token=cats["vehicle.truck"]) for i in d if i["token"] == instance
        ],
    )
    _edit(
        root_dir / "commands" / "train_commands.json",
        lambda d: d["commands"][0].update(obj_name="vehicle.truck"),
    )
    cs = read_commands(root_dir / "commands", "train", NuScenesRoot(root_dir))
    assert cs.skipped == {"category outside the class set: vehicle.truck": 1}


def test_malformed_files_name_file_record_and_field(exported: Path, tmp_path: Path) -> None:
    root_dir = tmp_path / "nusc"
    shutil.copytree(exported, root_dir)
    poses = root_dir / "v1.0-trainval" / "ego_pose.json"
    _edit(poses, lambda d: d[2].update(rotation=[1, 0, 0]))
    with pytest.raises(
        NuScenesError, match=r"ego_pose\.json: record 2 \(token \w+\): field 'rotation'"
    ):
        NuScenesRoot(root_dir)
    _edit(poses, lambda d: d[2].update(rotation=[1, 0, 0, 0]))
    (root_dir / "v1.0-mini").mkdir()
    with pytest.raises(
        NuScenesError, match=r"2 \(v1.0-mini, v1.0-trainval\) nuScenes version folders"
    ):
        NuScenesRoot(root_dir)
    root = NuScenesRoot(root_dir, version="v1.0-trainval")
    cmd_file = root_dir / "all" / "all_commands.json"
    _edit(cmd_file, lambda d: d["commands"][1].update(rotation=["1", "x", "0", "0"]))
    with pytest.raises(
        CommandFileError, match=r"all_commands\.json: command 1 \(\w+\): field 'rotation'"
    ):
        read_commands(root_dir / "all", "all", root)
    _edit(cmd_file, lambda d: d["commands"][1].pop("2d_box"))
    with pytest.raises(CommandFileError, match=r"command 1 .*field '2d_box' is missing"):
        read_commands(root_dir / "all", "all", root)
    lidar = next((root_dir / "samples" / "LIDAR_TOP").iterdir())
    lidar.write_bytes(lidar.read_bytes()[:-4])
    with pytest.raises(SensorFileError, match="not a whole number"):
        read_lidar(lidar)


def test_empty_radar_sweep(tmp_path: Path) -> None:
    path = tmp_path / "r.pcd"
    write_radar(path, np.zeros(0, dtype=radar_dtype()))
    raw = path.read_bytes()
    assert raw.endswith(empty_radar().tobytes() + b"\x00")  # one NaN point, one byte after it
    assert b"WIDTH 1\n" in raw
    assert len(read_radar(path)) == 0
    rec = np.zeros(3, dtype=radar_dtype())
    rec["x"], rec["rcs"] = [1, 2, 3], [4, 5, 6]
    write_radar(path, rec)
    np.testing.assert_array_equal(read_radar(path), rec)
    path.write_bytes(path.read_bytes().replace(b"SIZE 4 4 4 1 2", b"SIZE 4 4 4 2 2"))
    with pytest.raises(SensorFileError, match="PCD SIZE"):
        read_radar(path)


def test_class_mapping() -> None:
    assert model_class("vehicle.car", ()) == "Car"
    assert model_class("human.pedestrian.police_officer", ()) == "Pedestrian"
    assert model_class("vehicle.bicycle", ("cycle.with_rider",)) == "Cyclist"
    assert model_class("vehicle.bicycle", ("cycle.without_rider",)) is None
    assert model_class("vehicle.truck", ()) is None
