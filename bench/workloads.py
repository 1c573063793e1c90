"""Workloads of the benchmarks: scenes and prompts drawn from the synthetic generator
(:func:`scenes.synth.synthesize`), so that point counts and prompts are the app's."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from model import TPCNet

WARM_UP_PROMPTS = ("the car ahead of us (warm-up)", "the pedestrians on the left (warm-up)")
"""Prompts of :func:`warm_up`, outside every measured set."""


def warm_up(model: TPCNet, lidar: np.ndarray, radar: np.ndarray) -> None:
    """Load MiniLM and make first-call allocations before timing: encode the scene of
    ``lidar (N, 4)`` and ``radar (M, 7)`` (LiDAR frame) and ground :data:`WARM_UP_PROMPTS`."""
    features = model.encode_scene(lidar, radar)
    for prompt in WARM_UP_PROMPTS:
        model.ground(features, prompt)


# --------------------------------------------------------------------------- workload


@dataclass(frozen=True)
class SceneWorkload:
    """One synthetic scene with its prompts, as the benchmarks feed it to the model.

    Attributes:
        world_index: Index of the world in the generator (``SeedSequence([seed, index])``).
        lidar: ``(N, 4)`` float32 LiDAR points, LiDAR frame (64-beam ray-cast, realistic counts).
        radar: ``(M, 7)`` float32 accumulated radar points, LiDAR frame.
        prompts: Prompt texts about the scene's sensed actors.
        boxes: Per prompt, the referents' boxes ``(K, 7)`` (LiDAR frame).
        classes: Per prompt, the referents' class names.
    """

    world_index: int
    lidar: Any
    radar: Any
    prompts: tuple[str, ...]
    boxes: tuple[Any, ...]
    classes: tuple[tuple[str, ...], ...]


def synthetic_scenes(
    worlds: int, prompts_per_world: int, seed: int = 0, first_world: int = 0
) -> list[SceneWorkload]:
    """Scenes from the synthetic generator (:func:`scenes.synth.synthesize`, default settings:
    clear weather, 5-scan radar) with up to ``prompts_per_world`` prompts each; worlds without a
    prompt are skipped."""
    import numpy as np

    from scenes.geometry.calib import sensor_to_lidar, vod_lidar_calibration, vod_radar_calibration
    from scenes.synth.generate import SynthSettings, synthesize

    settings = SynthSettings(seed=seed, prompts_per_world=prompts_per_world)
    radar_to_lidar = sensor_to_lidar(vod_lidar_calibration(), vod_radar_calibration())
    out = []
    for index in range(first_world, first_world + worlds):
        frame = synthesize(settings, index, radar_to_lidar)
        if not frame.prompts:
            continue
        by_id = {a.actor_id: a for a in frame.world.actors}
        boxes, classes = [], []
        for prompt in frame.prompts:
            referents = [by_id[i] for i in prompt.referent_ids]
            boxes.append(np.array([a.box for a in referents], dtype=np.float64).reshape(-1, 7))
            classes.append(tuple(a.cls for a in referents))
        out.append(
            SceneWorkload(
                world_index=index,
                lidar=np.ascontiguousarray(frame.lidar.points, dtype=np.float32),
                radar=np.ascontiguousarray(frame.radar.points, dtype=np.float32),
                prompts=tuple(p.text for p in frame.prompts),
                boxes=tuple(boxes),
                classes=tuple(classes),
            )
        )
    return out
