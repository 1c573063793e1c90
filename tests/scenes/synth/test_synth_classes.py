"""The synthetic world's class sets (issue 36, item 2): ``--classes vod`` (the default) writes
exactly what it always wrote, and ``--classes nuscenes`` populates worlds with every road user of
the nuScenes detection classes, with believable sizes, speeds, placement, LiDAR shapes and radar
signatures, and prompts about them whose labels name them."""

from __future__ import annotations

import hashlib
from collections import Counter

import numpy as np
import pytest

from scenes.geometry.classes import NUSCENES
from scenes.synth.frame import world_streams
from scenes.synth.generate import main
from scenes.synth.lidar import LidarConfig, simulate_lidar
from scenes.synth.radar import RadarConfig
from scenes.synth.sensors import sensor_set
from scenes.synth.world import RayCaster, WorldConfig, generate_world
from scenes.talk2radar.root import Talk2RadarRoot
from tests.synth_pins import differences, write_case

NEW_CLASSES = set(NUSCENES.names) - {"Car", "Pedestrian"}


def test_the_default_class_set_writes_what_it_always_wrote(tmp_path):
    """Two tiny default-class roots, pinned on the code before class sets reached the world
    (commit 8ef1a5a; ``tests/synth_pins.py``)."""
    for case in ("base", "extended"):
        write_case(case, tmp_path / case)
        changed = differences(tmp_path / case, case)
        assert not changed, "\n".join(changed[:8])


def _nuscenes_worlds(count: int, seed: int = 0):
    config = WorldConfig(classes="nuscenes")
    return [generate_world(world_streams(seed, i)["world"], i, config) for i in range(count)]


@pytest.fixture(scope="module")
def worlds():
    return _nuscenes_worlds(30)


def test_nuscenes_worlds_hold_every_road_user_at_believable_sizes_and_speeds(worlds):
    counts: Counter[str] = Counter()
    sizes: dict[str, list[np.ndarray]] = {}
    for world in worlds:
        for a in world.actors:
            counts[a.cls] += 1
            sizes.setdefault(a.cls, []).append(a.box[3:6])
            if a.cls in ("TrafficCone", "Barrier"):
                assert a.speed == 0.0
        assert not any(c.cls in ("bicycle", "moped_scooter") for c in world.clutter)
    assert set(counts) == set(NUSCENES.names), counts
    for cls in NUSCENES.names:
        mean = np.mean(sizes[cls], axis=0)
        expected = np.array(NUSCENES.get(cls).mean_size)
        assert np.all(np.abs(mean - expected) < 0.35 * expected), (cls, mean, expected)
    speeds = {c: [a.speed for w in worlds for a in w.actors if a.cls == c] for c in NUSCENES.names}
    assert max(speeds["Truck"]) > 3.0 and min(speeds["Truck"]) == 0.0  # moving and parked
    assert max(speeds["Motorcycle"]) > 3.0 and min(speeds["Motorcycle"]) == 0.0
    assert max(speeds["ConstructionVehicle"]) <= 1.5


def test_trailers_follow_their_trucks_and_buses_stop_by_the_kerb(worlds):
    towed = 0
    for world in worlds:
        trucks = [a for a in world.actors if a.cls == "Truck"]
        for t in (a for a in world.actors if a.cls == "Trailer" and a.speed > 0):
            tractor = min(trucks, key=lambda k: np.hypot(*(k.box[:2] - t.box[:2])))
            gap = np.hypot(*(tractor.box[:2] - t.box[:2])) - (tractor.box[3] + t.box[3]) / 2
            assert 0.0 < gap < 0.5 and abs(tractor.speed - t.speed) < 1e-9
            # same heading up to the road's curvature between them
            assert abs(np.sin(tractor.box[6] - t.box[6])) < 0.1
            towed += 1
    assert towed >= 1
    # A bus at a stop stands by the kerb (in the parking strip where the side has one).
    at_kerb = 0
    for world in worlds:
        road = world.road
        for bus in (a for a in world.actors if a.cls == "Bus"):
            x, y = bus.box[:2]
            theta = np.arctan(road.curvature * x)
            lateral = (y - road.centre(x)[1]) * np.cos(theta)  # s of the bus centre
            side = road.right if lateral < 0 else road.left
            if side.parking is not None:
                kerb = sum(side.parking) / 2
            else:
                kerb = side.carriageway_edge - side.sign * (bus.box[4] / 2 + 0.25)
            at_kerb += abs(lateral - kerb) < 0.3
    assert at_kerb >= 2, at_kerb


def test_the_lidar_sees_a_bus_as_a_bus_and_a_cone_as_a_cone(worlds):
    lidar = LidarConfig()
    checked = Counter()
    for world in worlds[:12]:
        scan = simulate_lidar(RayCaster(world), np.random.default_rng(0), lidar)
        for i, a in enumerate(world.actors):
            pts = scan.points[scan.owner == i, :3]
            if a.cls not in ("Bus", "TrafficCone") or len(pts) < (50 if a.cls == "Bus" else 15):
                continue
            height = pts[:, 2].max() - (a.box[2] - a.box[5] / 2)
            if a.cls == "Bus":  # a tall solid (no car reaches 2 m), wider than a car
                assert height > 2.0 and np.ptp(pts[:, :2], axis=0).max() > 2.0, height
            else:
                spread = np.ptp(pts[:, :2], axis=0).max()
                assert height < 1.5 and spread < 0.6, (height, spread)
            checked[a.cls] += 1
    assert checked["Bus"] >= 1 and checked["TrafficCone"] >= 1, checked


def test_radar_signatures_rank_the_road_users():
    for config in (RadarConfig(), sensor_set("nuscenes").radars[0].config):
        side = {c: config.class_model(c).rcs_side for c in NUSCENES.names}
        assert side["Bus"] > side["Truck"] > side["Car"] > side["Motorcycle"]
        assert side["Motorcycle"] > side["Bicycle"] > side["TrafficCone"]
        assert side["Pedestrian"] > side["TrafficCone"]
    with pytest.raises(KeyError, match="Tram"):
        RadarConfig().class_model("Tram")


def test_a_nuscenes_root_labels_and_prompts_name_the_road_users(tmp_path):
    out = tmp_path / "nus"
    argv = ["--out", str(out), "--frames", "16", "--seed", "4", "--classes", "nuscenes"]
    assert main([*argv, "--no-camera", "--quiet", "--split-fractions", "0", "0", "1"]) == 0
    root = Talk2RadarRoot(out)
    named = set()
    for sid in root.ids("test"):
        sample = root.load(sid)
        meta = sample.meta
        assert meta is not None
        by_id = {a.actor_id: a for a in meta.actors}
        classes = [o.name for o in sample.labels]  # the label_2 names, as written
        assert classes == [by_id[i].cls for i in meta.referent_ids]
        assert set(classes) <= set(NUSCENES.names)
        named |= set(classes)
    assert len(named & NEW_CLASSES) >= 3, named
    assert '"classes": "nuscenes"' in (out / "synth_manifest.jsonl").read_text().splitlines()[0]


def _set_digest(ids: frozenset[str]) -> str:
    return hashlib.sha256("\n".join(sorted(ids)).encode()).hexdigest()


def test_the_vod_wording_and_its_train_heldout_split_are_unmoved():
    """The road users' words join the tables without moving a vod variant across the split
    (the ids of every variant that is not only a road user's, of the command templates and of
    the out-of-class nouns, as on 8ef1a5a); fails when a road-user text is added to a group's
    ``more`` side or repeats a held-out-able text there as ``core``."""
    from scenes.language.prompts.commands import COMMAND_HELDOUT, COMMAND_SLOTS, COMMAND_TRAIN
    from scenes.language.prompts.nouns import HELDOUT_NOUNS
    from scenes.language.prompts.phrasing.slots import ROAD_USER_SLOTS, SLOTS
    from scenes.language.prompts.phrasing.split import HELDOUT_VARIANTS, TRAIN_VARIANTS, variant_id

    def ids(slots: dict, names) -> set[str]:
        return {variant_id(n, t) for n in names for t in slots[n].core + slots[n].more}

    road_commands = [n for n in COMMAND_SLOTS if n.split("/")[1].split("_")[0] in _ROAD_USER_KEYS]
    other_commands = [n for n in COMMAND_SLOTS if n not in road_commands]
    new = ids(SLOTS, ROAD_USER_SLOTS) - ids(SLOTS, [n for n in SLOTS if n not in ROAD_USER_SLOTS])
    new_commands = ids(COMMAND_SLOTS, road_commands) - ids(COMMAND_SLOTS, other_commands)
    assert new and new_commands
    assert _set_digest(HELDOUT_VARIANTS - new) == (
        "0824bfc5e37d1f6ba57ee0df248a8ecdaf950161bc5d16bb8004d5c6b9d8dfd9"
    )
    assert _set_digest(TRAIN_VARIANTS - new) == (
        "ef40194723b6d8fcb01f52f6065c4f775e3d0b27be1dbb087d534c37a4eee1bd"
    )
    assert _set_digest(COMMAND_HELDOUT - new_commands) == (
        "e6fe1189ae3d71d6209ac6af5f8168209ec355ac43be19e22223fde021b3c5ad"
    )
    assert _set_digest(COMMAND_TRAIN - new_commands) == (
        "1b6571a08948835bc8c6f28efe68ad1e622dabb8d279c1931e43df227722f226"
    )
    assert _set_digest(HELDOUT_NOUNS) == (
        "8ab3a7d5e2df35f059c1da49b6c6199961299cbed3185e7ed0ffe6ee40c186b9"
    )


_ROAD_USER_KEYS = ("truck", "bus", "motorcycle", "traffic", "barrier")
