"""An independent converter: a synthetic root written as a nuScenes root with Talk2Car commands
WITHOUT the project's writer (``scenes.nuscenes``), from the facts of the release alone
(``../shared/specs/nuscenes-talk2car.md``), as someone else's converter might write it. What our
export and our reader could agree on but the release does not is what this catches.

Deliberately unlike ``scenes.nuscenes.export`` wherever the release allows: random uuid-style
tokens (not name hashes), tables and commands in shuffled order, the release's LIDAR_TOP and
CAM_FRONT calibrated poses (a LIDAR_TOP rotation ~1 degree off a pure -90 degree turn, a camera a
little off the ego axes), a random global pose per sample with roll, pitch, yaw, height, and its
own timestamps (CAM_FRONT 12 ms after LIDAR_TOP, each radar 3-45 ms earlier, older radar sweeps
74 ms apart, the ego moving meanwhile), nuScenes' log-style file names, radar points that the
devkit's default filters drop (and an empty sweep: one NaN point), categories drawn among the
class's nuScenes names (a pedestrian is an adult, a child or a police officer), ``2d_box`` as
integers, and, optionally, each description wrapped into a driving instruction by templates of
its own.

The source (``python -m scenes.synth``, with sidecars) is in the model frame (x forward, y left,
z up, origin at the LiDAR); nuScenes' LIDAR_TOP frame is that turned so that x points right,
y forward (``MODEL_TO_LIDAR``). Every class of the source is written: cars, pedestrians and
cyclists, and a ``--classes nuscenes`` source's trucks, buses (rigid or bendy), trailers,
construction vehicles, motorcycles, bicycles, traffic cones and barriers, each under the release's
category and attribute (:func:`attribute_of`). Quaternions are scipy's, turned to nuScenes' w x y z order here.
"""

from __future__ import annotations

import argparse
import json
import random
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image
from scipy.spatial.transform import Rotation

from scenes.talk2radar.root import Talk2RadarRoot

MODEL_TO_LIDAR = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
"""Model frame (x forward, y left) -> LIDAR_TOP (x right, y forward): p_lidar = M @ p_model."""
LIDAR_CS = ([0.985793, 0.0, 1.84019], [0.706749, -0.015301, 0.017397, -0.707085])
"""LIDAR_TOP's calibrated_sensor (translation, rotation w x y z) as the release has it."""
CAMERA_CS = ([1.70079, 0.0159456, 1.51095], [0.499630, -0.503057, 0.499715, -0.497586])
"""CAM_FRONT's calibrated_sensor (x right, y down, z forward) as the release has it."""
INTRINSIC = [[1266.417, 0.0, 816.267], [0.0, 1266.417, 491.507], [0.0, 0.0, 1.0]]
"""CAM_FRONT's intrinsics (1600 x 900)."""
IMAGE_SIZE = (1600, 900)
RADARS = {
    "RADAR_FRONT": ([3.412, 0.0, 0.5], 0.0),
    "RADAR_FRONT_LEFT": ([2.422, 0.800, 0.78], 1.54),
    "RADAR_FRONT_RIGHT": ([2.422, -0.800, 0.77], -1.52),
    "RADAR_BACK_LEFT": ([-0.562, 0.628, 0.53], 3.05),
    "RADAR_BACK_RIGHT": ([-0.562, -0.618, 0.53], -3.12),
}
"""The five radars: translation in the ego frame, yaw of the boresight (radians)."""
CATEGORY_NAMES = (
    "animal", "human.pedestrian.adult", "human.pedestrian.child",
    "human.pedestrian.construction_worker", "human.pedestrian.personal_mobility",
    "human.pedestrian.police_officer", "human.pedestrian.stroller", "human.pedestrian.wheelchair",
    "movable_object.barrier", "movable_object.debris", "movable_object.pushable_pullable",
    "movable_object.trafficcone", "static_object.bicycle_rack", "vehicle.bicycle",
    "vehicle.bus.bendy", "vehicle.bus.rigid", "vehicle.car", "vehicle.construction",
    "vehicle.emergency.ambulance", "vehicle.emergency.police", "vehicle.motorcycle",
    "vehicle.trailer", "vehicle.truck",
)  # fmt: skip
ATTRIBUTE_NAMES = (
    "vehicle.moving", "vehicle.stopped", "vehicle.parked", "cycle.with_rider",
    "cycle.without_rider", "pedestrian.sitting_lying_down", "pedestrian.standing",
    "pedestrian.moving",
)  # fmt: skip
CLASS_CATEGORIES = {
    "Car": ("vehicle.car",),
    "Pedestrian": ("human.pedestrian.adult", "human.pedestrian.child",
                   "human.pedestrian.police_officer"),
    "Cyclist": ("vehicle.bicycle",),
    # a --classes nuscenes source: the release's categories of each detection class
    "Truck": ("vehicle.truck",),
    "Bus": ("vehicle.bus.rigid", "vehicle.bus.bendy"),
    "Trailer": ("vehicle.trailer",),
    "ConstructionVehicle": ("vehicle.construction",),
    "Motorcycle": ("vehicle.motorcycle",),
    "Bicycle": ("vehicle.bicycle",),
    "TrafficCone": ("movable_object.trafficcone",),
    "Barrier": ("movable_object.barrier",),
}  # fmt: skip
VEHICLES = ("Car", "Truck", "Bus", "Trailer", "ConstructionVehicle")
CYCLES = ("Cyclist", "Motorcycle", "Bicycle")


def attribute_of(cls: str, moving: bool, rng: random.Random) -> list[str]:
    """The release's attribute of an annotation: vehicles moving, parked or stopped; pedestrians
    moving or standing; two-wheelers with or without a rider (a VoD cyclist always has one);
    cones and barriers none."""
    if cls in VEHICLES:
        return ["vehicle.moving" if moving else rng.choice(["vehicle.parked", "vehicle.stopped"])]
    if cls == "Pedestrian":
        return ["pedestrian.moving" if moving else "pedestrian.standing"]
    if cls in CYCLES:
        ridden = cls == "Cyclist" or moving or rng.random() < 0.5
        return ["cycle.with_rider" if ridden else "cycle.without_rider"]
    return []


RADAR_FIELDS = "x y z dyn_prop id rcs vx vy vx_comp vy_comp is_quality_valid ambig_state x_rms y_rms invalid_state pdh0 vx_rms vy_rms"
RADAR_SIZES = "4 4 4 1 2 4 4 4 4 4 1 1 1 1 1 1 1 1"
RADAR_TYPES = "F F F I I F F F F F I I I I I I I I"
RADAR_DTYPE = np.dtype(
    [(n, {"F4": "<f4", "I1": "i1", "I2": "<i2"}[t + s])
     for n, s, t in zip(RADAR_FIELDS.split(), RADAR_SIZES.split(), RADAR_TYPES.split(), strict=True)]
)  # fmt: skip
COMMAND_TEMPLATES = (
    "pull over behind {d}", "stop next to {d}", "keep a safe distance from {d}",
    "slow down, watch out for {d}", "follow {d} for a while", "let {d} go first",
    "park near {d} please", "be careful with {d}",
)  # fmt: skip
"""This converter's own command wordings (``wrap=True``); ``{d}`` is the source's description."""


def _wxyz(rot: Rotation) -> list[float]:
    x, y, z, w = rot.as_quat()
    return [float(w), float(x), float(y), float(z)]


def _rot(wxyz: list[float]) -> Rotation:
    w, x, y, z = wxyz
    return Rotation.from_quat([x, y, z, w])


def _pose(translation: list[float] | np.ndarray, rot: Rotation) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = rot.as_matrix()
    out[:3, 3] = translation
    return out


def _apply(m: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ m[:3, :3].T + m[:3, 3]


def write_radar_pcd(path: Path, points: np.ndarray) -> None:
    """A PCD v0.7 binary radar file of a structured ``RADAR_DTYPE`` array (one NaN point when
    empty), with a trailing byte as the release's files have."""
    if len(points) == 0:
        points = np.zeros(1, RADAR_DTYPE)
        for name in ("x", "y", "z", "rcs", "vx", "vy", "vx_comp", "vy_comp"):
            points[name] = np.nan
    head = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        f"FIELDS {RADAR_FIELDS}\nSIZE {RADAR_SIZES}\nTYPE {RADAR_TYPES}\n"
        f"COUNT {' '.join(['1'] * 18)}\nWIDTH {len(points)}\nHEIGHT 1\n"
        f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(points)}\nDATA binary\n"
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(head.encode() + points.astype(RADAR_DTYPE).tobytes() + b"\n")


@dataclass
class _Db:
    """The 13 tables being written."""

    tables: dict[str, list[dict]]
    rng: random.Random

    def token(self) -> str:
        return uuid.UUID(int=self.rng.getrandbits(128), version=4).hex

    def add(self, table: str, **record: object) -> dict:
        record = {"token": self.token(), **record}
        self.tables[table].append(record)
        return record


def _box_corners(box: np.ndarray) -> np.ndarray:
    """``(8, 3)`` corners of a model-frame box ``x, y, z, l, w, h, yaw`` (z = centre)."""
    x, y, z, length, width, height, yaw = box
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    local = signs * np.array([length, width, height]) / 2
    c, s = np.cos(yaw), np.sin(yaw)
    return local @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + np.array([x, y, z])


def convert(
    source: str | Path, out: str | Path, seed: int = 0, wrap: bool = False
) -> dict[str, int]:
    """Write the synthetic root ``source`` (its train, val and test lists) as a nuScenes root
    (``out/v1.0-trainval``, ``samples/``, ``sweeps/``, ``maps/``) with Talk2Car commands
    (``out/commands/{split}_commands.json``) from its single-referent prompts wholly inside the
    CAM_FRONT image; ``wrap``: the sentence wrapped by :data:`COMMAND_TEMPLATES`. Returns the
    command count per split."""
    src, out = Talk2RadarRoot(source, radar="auto"), Path(out)
    rng = random.Random(seed)
    nrng = np.random.default_rng(seed)
    names = ("category", "attribute", "visibility", "instance", "sensor", "calibrated_sensor",
             "ego_pose", "log", "scene", "sample", "sample_data", "sample_annotation", "map")  # fmt: skip
    db = _Db({n: [] for n in names}, rng)
    category = {
        n: db.add("category", name=n, description=f"{n}.", index=i)["token"]
        for i, n in enumerate(CATEGORY_NAMES)
    }
    attribute = {n: db.add("attribute", name=n, description=n)["token"] for n in ATTRIBUTE_NAMES}
    for i, level in enumerate(("v0-40", "v40-60", "v60-80", "v80-100")):
        db.tables["visibility"].append({"token": str(i + 1), "level": level, "description": level})
    sensor = {}
    for ch in ("CAM_FRONT", "LIDAR_TOP", *RADARS):
        modality = "camera" if ch.startswith("CAM") else ch.split("_")[0].lower()
        sensor[ch] = db.add("sensor", channel=ch, modality=modality)["token"]
    log = db.add("log", logfile="n015-2018-07-24-11-22-45+0800", vehicle="n015",
                 date_captured="2018-07-24", location="singapore-onenorth")  # fmt: skip
    db.add("map", category="semantic_prior", filename="maps/53992ee3023e5494b90c316c183be829.png",
           log_tokens=[log["token"]])  # fmt: skip
    (out / "maps").mkdir(parents=True, exist_ok=True)
    Image.new("L", (8, 8)).save(out / "maps" / "53992ee3023e5494b90c316c183be829.png")
    cs = {
        "LIDAR_TOP": db.add("calibrated_sensor", sensor_token=sensor["LIDAR_TOP"],
                            translation=LIDAR_CS[0], rotation=LIDAR_CS[1], camera_intrinsic=[]),
        "CAM_FRONT": db.add("calibrated_sensor", sensor_token=sensor["CAM_FRONT"],
                            translation=CAMERA_CS[0], rotation=CAMERA_CS[1],
                            camera_intrinsic=INTRINSIC),
    }  # fmt: skip
    for ch, (t, yaw) in RADARS.items():
        rot = _wxyz(Rotation.from_euler("z", yaw))
        cs[ch] = db.add("calibrated_sensor", sensor_token=sensor[ch], translation=t,
                        rotation=rot, camera_intrinsic=[])  # fmt: skip
    cs_pose = {ch: _pose(r["translation"], _rot(r["rotation"])) for ch, r in cs.items()}
    # model frame -> LIDAR_TOP -> ego
    lidar_to_model = np.eye(4)
    lidar_to_model[:3, :3] = MODEL_TO_LIDAR.T
    ego_from_model = cs_pose["LIDAR_TOP"] @ np.linalg.inv(lidar_to_model)

    frames: dict[tuple, dict] = {}
    for split in ("train", "val", "test"):
        for sid in src.ids(split):
            meta = src.load_meta(sid)
            key = src.frame_key(sid)
            if key not in frames:
                frames[key] = {"sid": sid, "meta": meta, "prompts": []}
            frames[key]["prompts"].append((split, sid, src.load_prompt(sid) or "", meta))
    scenes: dict[int, dict] = {}
    commands: dict[str, list[dict]] = {"train": [], "val": [], "test": []}
    split_scenes: dict[str, list[str]] = {"train": [], "val": [], "test": []}
    time_us = 1532402927647951
    k_cam = np.array(INTRINSIC)
    for frame in frames.values():
        meta = frame["meta"]
        sample_src = src.load(frame["sid"])
        time_us += 500_000 + rng.randrange(1000)
        world = meta.world_id
        if world not in scenes:
            description = {"rain": "Rain, wet road, ", "fog": "Fog, "}.get(meta.weather, "")
            scenes[world] = db.add("scene", log_token=log["token"], nbr_samples=0,
                                   first_sample_token="", last_sample_token="",
                                   name=f"scene-{len(scenes) + 1:04d}",
                                   description=f"{description}peds, parked cars, intersection")  # fmt: skip
            scenes[world]["_samples"] = []
            scenes[world]["_instances"] = {}
        scene = scenes[world]
        sample = db.add("sample", timestamp=time_us, prev="", next="", scene_token=scene["token"])
        if scene["_samples"]:
            scene["_samples"][-1]["next"] = sample["token"]
            sample["prev"] = scene["_samples"][-1]["token"]
        scene["_samples"].append(sample)
        # the ego at the key LIDAR_TOP time: a random global pose; it moves along its x
        base = _pose(
            [rng.uniform(-2000, 2000), rng.uniform(-2000, 2000), rng.uniform(-1, 1)],
            Rotation.from_euler(
                "zyx", [rng.uniform(-np.pi, np.pi), rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02)]
            ),
        )  # fmt: skip
        speed = float(meta.ego_velocity)

        def ego_at(dt_us: int, base: np.ndarray = base, speed: float = speed) -> np.ndarray:
            step = np.eye(4)
            step[0, 3] = speed * dt_us * 1e-6
            return base @ step

        global_from_model = base @ ego_from_model

        def sample_data(
            ch: str,
            dt_us: int,
            key: bool,
            ext: str,
            sample: dict = sample,
            time_us: int = time_us,
            global_from_model: np.ndarray = global_from_model,
        ) -> tuple:
            pose = ego_at(dt_us)
            ego = db.add("ego_pose", timestamp=time_us + dt_us, translation=list(pose[:3, 3]),
                         rotation=_wxyz(Rotation.from_matrix(pose[:3, :3])))  # fmt: skip
            folder = "samples" if key else "sweeps"
            name = f"{folder}/{ch}/{log['logfile']}__{ch}__{time_us + dt_us}.{ext}"
            rec = db.add("sample_data", sample_token=sample["token"], ego_pose_token=ego["token"],
                         calibrated_sensor_token=cs[ch]["token"], timestamp=time_us + dt_us,
                         fileformat=ext.split(".")[0] if ext != "pcd.bin" else "pcd",
                         is_key_frame=key, height=IMAGE_SIZE[1] if ch == "CAM_FRONT" else 0,
                         width=IMAGE_SIZE[0] if ch == "CAM_FRONT" else 0, filename=name,
                         prev="", next="")  # fmt: skip
            # sensor frame <- model frame (key time): sensor <- ego(t) <- global <- model
            sensor_from_model = np.linalg.inv(cs_pose[ch]) @ np.linalg.inv(pose) @ global_from_model
            (out / name).parent.mkdir(parents=True, exist_ok=True)
            return rec, sensor_from_model, out / name

        # LIDAR_TOP key frame
        lidar = np.asarray(sample_src.lidar, dtype=np.float64)
        rec, to_sensor, path = sample_data("LIDAR_TOP", 0, True, "pcd.bin")
        xyz = _apply(to_sensor, lidar[:, :3])
        ring = np.clip(
            np.round((np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1]))) + 30) * 1),
            0, 31,
        )  # fmt: skip
        np.c_[xyz, lidar[:, 3], ring].astype("<f4").tofile(path)
        # radars: each point to the radar facing it; older scans as sweeps (prev links)
        radar = np.asarray(sample_src.radar, dtype=np.float64)
        ego_points = _apply(ego_from_model, radar[:, :3]) if len(radar) else np.zeros((0, 3))
        scans = sorted({int(round(-t)) for t in radar[:, 6]}) if len(radar) else [0]
        azimuth = np.arctan2(ego_points[:, 1], ego_points[:, 0])
        facing = np.argmin(
            [np.abs(np.angle(np.exp(1j * (azimuth - y)))) for _, y in RADARS.values()], axis=0
        )
        for r, ch in enumerate(RADARS):
            mine = facing == r
            later = None
            for k in sorted(scans, reverse=True):  # oldest first
                dt = -rng.randrange(3_000, 45_000) - 74_000 * k
                rec, to_sensor, path = sample_data(ch, dt, k == 0, "pcd")
                if later is not None:
                    later["next"], rec["prev"] = rec["token"], later["token"]
                later = rec
                sel = radar[mine & (np.round(-radar[:, 6]) == k)]
                pts = np.zeros(len(sel), RADAR_DTYPE)
                p = _apply(to_sensor, sel[:, :3])
                los = p[:, :2] / np.maximum(np.linalg.norm(p[:, :2], axis=1, keepdims=True), 1e-9)
                pts["x"], pts["y"], pts["z"] = p.T
                pts["rcs"] = sel[:, 3]
                pts["vx"], pts["vy"] = (los * sel[:, 4:5]).T
                pts["vx_comp"], pts["vy_comp"] = (los * sel[:, 5:6]).T
                pts["dyn_prop"] = nrng.choice([0, 1, 2, 3], len(sel))
                pts["id"] = np.arange(len(sel))
                pts["ambig_state"], pts["invalid_state"], pts["is_quality_valid"] = 3, 0, 1
                pts["pdh0"], pts["x_rms"], pts["y_rms"] = 1, 5, 5
                # a point the devkit's default filters drop (invalid state)
                junk = np.zeros(1, RADAR_DTYPE)
                junk["x"], junk["y"], junk["z"], junk["invalid_state"], junk["ambig_state"] = (
                    20,
                    1,
                    0,
                    4,
                    3,
                )
                pts = np.concatenate([pts, junk]) if len(pts) and rng.random() < 0.5 else pts
                write_radar_pcd(path, pts)
        # CAM_FRONT, 12 ms later
        cam, model_to_cam, path = sample_data("CAM_FRONT", 12_000, True, "jpg")
        Image.new("RGB", IMAGE_SIZE, (90, 90, 90)).save(path, quality=50)
        # annotations: global boxes, size w l h
        ann_token = {}
        for actor in meta.actors:
            box = np.asarray(actor.box, dtype=np.float64)
            inst = scene["_instances"].get(actor.actor_id)
            if inst is None:
                name = rng.choice(CLASS_CATEGORIES[actor.cls])
                inst = db.add("instance", category_token=category[name], nbr_annotations=0,
                              first_annotation_token="", last_annotation_token="")  # fmt: skip
                inst["_name"] = name
                scene["_instances"][actor.actor_id] = inst
            moving = float(np.hypot(*actor.velocity)) > 0.2
            attrs = attribute_of(actor.cls, moving, rng)
            rot = Rotation.from_matrix(global_from_model[:3, :3]) * Rotation.from_euler("z", box[6])
            ann = db.add("sample_annotation", sample_token=sample["token"],
                         instance_token=inst["token"], visibility_token=str(rng.randint(1, 4)),
                         attribute_tokens=[attribute[a] for a in attrs],
                         translation=list(_apply(global_from_model, box[None, :3])[0]),
                         size=[float(box[4]), float(box[3]), float(box[5])], rotation=_wxyz(rot),
                         prev=inst["last_annotation_token"], next="",
                         num_lidar_pts=int(rng.randint(1, 300)), num_radar_pts=int(rng.randint(0, 9)))  # fmt: skip
            if not inst["first_annotation_token"]:
                inst["first_annotation_token"] = ann["token"]
            else:
                next(a for a in db.tables["sample_annotation"] if a["token"] == ann["prev"])[
                    "next"
                ] = ann["token"]
            inst["last_annotation_token"] = ann["token"]
            inst["nbr_annotations"] += 1
            ann_token[actor.actor_id] = (ann, inst, box)
        # commands: a single-referent prompt whose box the camera sees whole
        for split, _, text, pmeta in frame["prompts"]:
            if scene["token"] not in split_scenes[split]:
                split_scenes[split].append(scene["token"])
            if len(pmeta.referent_ids) != 1 or not text:
                continue
            ann, inst, box = ann_token[pmeta.referent_ids[0]]
            corners = _apply(model_to_cam, _box_corners(box))
            if (corners[:, 2] < 0.5).any():
                continue
            uv = corners @ k_cam.T
            uv = uv[:, :2] / uv[:, 2:]
            x0, y0 = np.maximum(uv.min(axis=0), 0)
            x1, y1 = np.minimum(uv.max(axis=0), IMAGE_SIZE)
            if x1 - x0 < 2 or y1 - y0 < 2:
                continue
            cam_rot = Rotation.from_matrix(model_to_cam[:3, :3]) * Rotation.from_euler("z", box[6])
            sentence = rng.choice(COMMAND_TEMPLATES).format(d=text.rstrip(".")) if wrap else text
            commands[split].append({
                "command_token": db.token(),
                "obj_name": inst["_name"],
                "command": sentence,
                "box_token": ann["token"],
                "sample_token": cam["token"],
                "scene_token": scene["token"],
                "translation": [float(v) for v in _apply(model_to_cam, box[None, :3])[0]],
                "size": [float(box[4]), float(box[3]), float(box[5])],
                "rotation": [str(v) for v in _wxyz(cam_rot)],
                "2d_box": [int(x0), int(y0), int(x1 - x0), int(y1 - y0)],
                "t2c_img": f"img_{split}_{len(commands[split])}.jpg",
            })  # fmt: skip
    for scene in scenes.values():
        samples = scene.pop("_samples")
        scene.pop("_instances")
        scene.update(nbr_samples=len(samples), first_sample_token=samples[0]["token"],
                     last_sample_token=samples[-1]["token"])  # fmt: skip
    for inst in db.tables["instance"]:
        inst.pop("_name")
    version = out / "v1.0-trainval"
    version.mkdir(parents=True, exist_ok=True)
    for name, records in db.tables.items():
        rng.shuffle(records)
        (version / f"{name}.json").write_text(json.dumps(records, indent=0))
    (out / "commands").mkdir(exist_ok=True)
    for split, cmds in commands.items():
        rng.shuffle(cmds)
        body = {"scene_tokens": split_scenes[split], "commands": cmds}
        (out / "commands" / f"{split}_commands.json").write_text(json.dumps(body))
    return {split: len(c) for split, c in commands.items()}


def build_parser() -> argparse.ArgumentParser:
    """``python -m tools.nuscenes_converter``'s parser."""
    p = argparse.ArgumentParser(prog="python -m tools.nuscenes_converter", description=__doc__)
    p.add_argument("source")
    p.add_argument("out")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--wrap", action="store_true", help="wrap descriptions into instructions")
    return p


def main(argv: list[str] | None = None) -> int:
    """``python -m tools.nuscenes_converter SOURCE OUT [--seed N] [--wrap]``."""
    a = build_parser().parse_args(argv)
    print(convert(a.source, a.out, a.seed, a.wrap))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
