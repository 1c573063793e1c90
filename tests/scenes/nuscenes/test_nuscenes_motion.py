"""The velocity of a nuScenes annotation where the release tells it (scenes.nuscenes.motion), and
label prompts that speak of motion only where the unknown ones cannot change the referents."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np

from scenes.geometry.actors import Actor
from scenes.language.prompts import PromptConfig
from scenes.language.prompts.generate import generate_prompts, motion_robust
from scenes.language.prompts.render import Prompt
from scenes.nuscenes.motion import attribute_velocity, combine, radar_velocity
from scenes.nuscenes.root import NuScenesRoot


def _radar(xy: list[tuple[float, float]], v_c: float, time: float = 0.0) -> np.ndarray:
    return np.array([[x, y, 0.5, 5.0, v_c, v_c, time] for x, y in xy], dtype=np.float32)


def test_radar_velocity_along_the_heading() -> None:
    # a car 20 m ahead driving towards us (heading -x), another 20 m left crossing, one without points
    boxes = np.array(
        [
            [20.0, 0.0, 0.0, 4.0, 1.8, 1.5, math.pi],
            [0.0, 20.0, 0.0, 4.0, 1.8, 1.5, 0.0],
            [30.0, -10.0, 0.0, 4.0, 1.8, 1.5, 0.0],
        ]
    )
    radar = np.concatenate(
        [
            _radar([(19.0, 0.2), (20.5, -0.3), (21.0, 0.0)], -8.0),
            _radar([(0.5, 19.5)], 0.1),
            _radar([(30.0, -10.0)], 3.0, time=-1.0),  # an older sweep: not used
        ]
    )
    v = radar_velocity(boxes, radar)
    np.testing.assert_allclose(v[0], [-8.0, 0.0], atol=1e-6)
    assert np.isnan(v[1]).all()  # across the line of sight: the radial speed says too little
    assert np.isnan(v[2]).all()
    # 45 degrees off the line of sight: v_r / cos
    skew = np.array([[20.0, 0.0, 0.0, 4.0, 1.8, 1.5, math.pi / 4]])
    np.testing.assert_allclose(
        radar_velocity(skew, _radar([(20.0, 0.0)], 2.0))[0],
        [2.0, 2.0],
        atol=1e-6,
    )


def test_attributes_and_the_order_of_sources() -> None:
    a = attribute_velocity([("vehicle.parked",), ("vehicle.moving",), ()])
    np.testing.assert_array_equal(a[0], [0.0, 0.0])
    assert np.isnan(a[1:]).all()
    radar = np.array([[1.0, 1.0], [3.0, 0.0], [np.nan, np.nan]])
    out = combine(a, radar)
    np.testing.assert_array_equal(out[:2], [[0.0, 0.0], [3.0, 0.0]])
    assert np.isnan(out[2]).all()


def test_neighbour_velocity_from_the_next_annotation(nuscenes_root: Path, tmp_path: Path) -> None:
    root_path = tmp_path / "nusc"
    shutil.copytree(nuscenes_root, root_path)
    tables = next(root_path.glob("v1.0-*"))
    anns = json.loads((tables / "sample_annotation.json").read_text())
    samples = {s["token"]: s for s in json.loads((tables / "sample.json").read_text())}
    first = anns[0]
    other = next(s for s in samples if s != first["sample_token"])
    samples[other]["timestamp"] = samples[first["sample_token"]]["timestamp"] + 500_000
    moved = dict(first, token="f" * 32, sample_token=other, prev=first["token"], next="")
    moved["translation"] = [first["translation"][0] + 2.0, *first["translation"][1:]]
    first["next"] = moved["token"]
    anns.append(moved)
    (tables / "sample_annotation.json").write_text(json.dumps(anns))
    (tables / "sample.json").write_text(json.dumps(list(samples.values())))

    root = NuScenesRoot(root_path)
    token = first["sample_token"]
    v = root.neighbour_velocities(token)
    index = root.annotations(token).index(first["token"])
    expected = (root.model_from_global(token)[:3, :3] @ np.array([4.0, 0.0, 0.0]))[:2]
    np.testing.assert_allclose(v[index], expected, atol=1e-6)
    assert np.isnan(np.delete(v, index, axis=0)).all()  # the others have no neighbour
    # too fast to be one world (a converter's independent global poses): unknown
    moved["translation"][0] += 500.0
    (tables / "sample_annotation.json").write_text(json.dumps(anns))
    assert np.isnan(NuScenesRoot(root_path).neighbour_velocities(token)[index]).all()
    # the frame carries them, with the attributes' and the radar's where the neighbours say nothing
    frame = NuScenesRoot(root_path).frame(token)
    assert frame.velocities is not None and frame.velocities.shape == (len(frame.boxes), 2)


def _scene() -> list[Actor]:
    """Two cars ahead, one moving towards us (known), one whose motion is unknown; a pedestrian."""
    return [
        Actor(0, "Car", np.array([15.0, 2.0, -0.8, 4.2, 1.8, 1.5, math.pi]), np.array([-8.0, 0.0])),
        Actor(1, "Car", np.array([30.0, -3.0, -0.8, 4.2, 1.8, 1.5, 0.0]), np.zeros(2)),
        Actor(2, "Pedestrian", np.array([12.0, 5.0, -0.9, 0.6, 0.6, 1.7, 0.0]), np.zeros(2)),
    ]


def test_motion_robust_keeps_what_the_unknown_cannot_change() -> None:
    from scenes.language.prompts.atoms import MotionState
    from scenes.language.prompts.predicate import Predicate

    actors = _scene()
    moving_cars = Prompt(
        "the moving car", (0,), frozenset({"velocity"}), Predicate("Car", (MotionState(True),))
    )
    pedestrians = Prompt("the pedestrian", (2,), frozenset({"class"}), Predicate("Pedestrian", ()))
    assert motion_robust(moving_cars, actors, ())  # nothing unknown
    assert not motion_robust(moving_cars, actors, {1})  # car 1 might move too
    assert motion_robust(pedestrians, actors, {1})  # no motion said
    assert motion_robust(moving_cars, actors, {2})  # another class


def test_label_prompts_with_unknown_motion_hold_under_every_hypothesis() -> None:
    actors = _scene()
    config = PromptConfig()
    said_motion = 0
    for seed in range(30):
        for p in generate_prompts(
            actors, np.random.default_rng(seed), 8, config=config, unknown_motion={1}
        ):
            assert motion_robust(p, actors, {1})
            said_motion += bool({"velocity", "motion"} & set(p.tags))
    assert said_motion > 0  # car 0's motion is known and is talked about


def _robust_by_definition(prompt: Prompt, actors, unknown) -> bool:
    """motion_robust's definition, brute force: every hypothesis given to every unknown actor,
    the whole scene resolved again."""
    from dataclasses import replace

    from scenes.language.prompts.generate import motion_hypotheses
    from scenes.language.prompts.predicate import analyse

    moved = [a for a in actors if a.actor_id in unknown]
    if not moved:
        return True
    hypotheses = [motion_hypotheses(a) for a in moved]
    for i in range(len(hypotheses[0])):
        velocity = {a.actor_id: h[i] for a, h in zip(moved, hypotheses, strict=True)}
        tried = [replace(a, velocity=velocity[a.actor_id]) if a.actor_id in velocity else a
                 for a in actors]  # fmt: skip
        res = analyse(prompt.predicate, tried)
        if not res.usable or res.ids != prompt.referent_ids:
            return False
    return True


def test_motion_robust_agrees_with_its_definition_on_random_scenes() -> None:
    """The fast path (a predicate that reads no velocity is robust at once; only the unknown
    actors' features are recomputed) decides every generated prompt as the brute force does."""
    rng = np.random.default_rng(3)
    config = PromptConfig()
    decided = {True: 0, False: 0}
    for scene in range(40):
        actors = []
        for i in range(int(rng.integers(3, 9))):
            cls = str(rng.choice(["Car", "Pedestrian", "Cyclist"]))
            box = np.array([rng.uniform(5, 45), rng.uniform(-12, 12), -0.8, 4, 1.8, 1.5,
                            rng.uniform(-np.pi, np.pi)])  # fmt: skip
            velocity = rng.normal(0, 3, 2) if rng.random() < 0.5 else np.zeros(2)
            actors.append(Actor(i, cls, box, velocity))
        unknown = {a.actor_id for a in actors if rng.random() < 0.4}
        for prompt in generate_prompts(actors, rng, 12, config=config):
            for u in (unknown, set()):
                fast = motion_robust(prompt, actors, u)
                assert fast == _robust_by_definition(prompt, actors, u), (scene, prompt.text)
                decided[fast] += 1
    assert decided[True] and decided[False]  # both outcomes were exercised
