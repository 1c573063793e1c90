"""Measurements of :mod:`bench.perf.latency`: the models of both grounding paths, the timed calls, the
stage timings from outside the model, the thread comparison and cProfile.

Each path is described by a :class:`PathSpec` (which :class:`model.core.features.GroundTimings` and
``SceneTimings`` fields its stages are). Timings are wall-clock milliseconds
(``time.perf_counter``, CUDA synchronised before each reading); what is timed is exactly what the
app calls: ``model.encode_scene(lidar, radar)`` and ``model.ground(features, prompt)``.
"""

from __future__ import annotations

import cProfile
import os
import pstats
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from bench.measure import synchronize
from bench.perf.model_parts import keep_candidates, model_parts
from bench.report import REPO
from bench.workloads import SceneWorkload
from model import (
    CheckpointMeta,
    SceneFeatures,
    TPCNet,
    as_points,
    build_model,
    decode,
    referent_head,
    referent_heatmap,
)

CHECKPOINT = REPO / "checkpoints" / "tpcnet-small.pt"
"""The checkpoint the app serves (``make run``): the referent path once it is trained for it."""
FAITHFUL_CHECKPOINT = REPO / "checkpoints" / "tpcnet-small-faithful.pt"
"""The paper's path (DGGF + C3D-RECHead ranking)."""

SCENE_STAGES = ("pillars", "backbone", "fusion")
GROUND_STAGES = ("text", "dggf", "neck", "head", "decode")


@dataclass(frozen=True)
class PathSpec:
    """One grounding path as the benchmark sees it.

    Attributes:
        key: ``ModelConfig.grounding`` (``"referent"`` or ``"tpcnet"``).
        label: Name in the tables.
        ground_stages: :class:`model.core.features.GroundTimings` fields that ``ground`` fills.
        scene_stages: :class:`model.core.features.SceneTimings` fields that ``encode_scene`` fills.
        stage_names: Table label of every stage.
    """

    key: str
    label: str
    ground_stages: tuple[str, ...]
    scene_stages: tuple[str, ...]
    stage_names: dict[str, str]


_COMMON_NAMES = {
    "text": "text encoder (MiniLM)",
    "pillars": "pillar encoders (both sensors)",
    "backbone": "backbones (both sensors)",
    "fusion": "fusion (BACA, 3 stages)",
}
REFERENT = PathSpec(
    key="referent",
    label="referent path",
    ground_stages=("text", "referent", "decode"),
    scene_stages=(*SCENE_STAGES, "detect"),
    stage_names={
        **_COMMON_NAMES,
        "referent": "referent stage (transformer over the candidates)",
        "decode": "answer (ranking, heatmap)",
        "detect": "detection (neck, head, decoding, candidates)",
    },
)
TPCNET = PathSpec(
    key="tpcnet",
    label="TPCNet path (DGGF)",
    ground_stages=GROUND_STAGES,
    scene_stages=SCENE_STAGES,
    stage_names={
        **_COMMON_NAMES,
        "dggf": "DGGF (3 stages)",
        "neck": "neck (FPN)",
        "head": "head (C3D-RECHead)",
        "decode": "decoding (peaks, NMS)",
    },
)
PATHS = (REFERENT, TPCNET)
DETECT_PARTS = ("neck", "head", "decode", "candidates")
"""The referent path's ``detect`` stage of ``encode_scene``, timed part by part from outside."""
DETECT_NAMES = {
    "neck": "neck (FPN)",
    "head": "head (C3D-RECHead, text-agnostic)",
    "decode": "decoding (peaks, rotated NMS)",
    "candidates": "candidate description (pooling, point evidence)",
}


@dataclass(frozen=True)
class Call:
    """One timed call: wall-clock milliseconds, the model's own stage times, boxes returned, and
    how many of them reach the model's operating threshold (its answer)."""

    wall_ms: float
    stages: dict[str, float]
    boxes: int
    answer: int = 0


@dataclass(frozen=True)
class PathCalls:
    """The timed calls of one path: ``ground`` on a cached scene, ``encode_scene`` + ``ground``
    and ``ground`` of a prompt seen before."""

    cached: list[Call]
    fresh: list[Call]
    repeated: list[Call]


@dataclass(frozen=True)
class LoadedModel:
    """A path's model and what it is: ``note`` (a sentence), ``short`` (for table cells)."""

    model: TPCNet
    note: str
    short: str
    trained: bool


def load_path_model(spec: PathSpec, preset: str, device: str) -> LoadedModel:
    """The model of one path, in eval mode.

    ``small`` on the referent path: ``checkpoints/tpcnet-small.pt`` when its grounding is
    ``referent``; on the TPCNet path ``checkpoints/tpcnet-small-faithful.pt`` (or
    ``tpcnet-small.pt``) when its grounding is ``tpcnet``. Otherwise (and for ``paper``) an
    untrained model of that grounding (seed 0); the note says which and why.
    """
    candidates = [CHECKPOINT] if spec.key == "referent" else [FAITHFUL_CHECKPOINT, CHECKPOINT]
    why = []
    if preset == "small":
        from model import CheckpointError, load_checkpoint, read_checkpoint

        for path in candidates:
            rel = path.relative_to(REPO)
            if not path.is_file():
                why.append(f"`{rel}` does not exist")
                continue
            try:
                grounding = read_checkpoint(path)["config"].get("grounding", "tpcnet")
            except CheckpointError as exc:
                why.append(f"`{rel}` cannot be read ({exc})")
                continue
            if grounding != spec.key:
                why.append(f"`{rel}` has grounding {grounding!r}")
                continue
            model = load_checkpoint(path, device=device)
            step = CheckpointMeta.of(model).step
            step = "?" if step is None else step
            return LoadedModel(
                model, f"trained checkpoint `{rel}` (step {step})", f"`{path.name}`", True
            )
    torch.manual_seed(0)
    model = build_model(preset, grounding=spec.key).to(device).eval()
    note = f"untrained `{preset}` model, grounding={spec.key!r} (random initialisation, seed 0)"
    if why:
        note += f", because {' and '.join(why)}"
    return LoadedModel(model, note, "untrained", False)


def text_cache(model: TPCNet, size: int) -> int:
    """Set the MiniLM prompt-cache size (0 = every prompt is encoded); returns the old size."""
    encoder = model.text_encoder
    old = int(getattr(encoder, "cache_size", 0))
    if hasattr(encoder, "cache_size"):
        encoder.cache_size = size
    return old


def prompt_pairs(scenes: list[SceneWorkload]) -> list[tuple[SceneWorkload, str]]:
    """Every (scene, prompt) of the workload, in order."""
    return [(s, p) for s in scenes for p in s.prompts]


def _answer(model: TPCNet, scores: np.ndarray) -> int:
    from model import operating_threshold

    return int(np.sum(scores >= operating_threshold(model)))


def measure_paths(
    models: dict[str, TPCNet], specs: dict[str, PathSpec], scenes: list[SceneWorkload], device: str
) -> dict[str, PathCalls]:
    """Per prompt and per path: ``ground`` on the scene encoded beforehand (cached path) and
    ``encode_scene`` + ``ground`` (new-scene path), then ``ground`` of a prompt already in the text
    cache. The paths take turns (their order alternates prompt by prompt, and so does the order of
    the cached and new-scene calls), so that all see the same machine load. The models' text
    caches must be off (size 0): every measured prompt is then new to the text encoder."""
    out = {key: PathCalls([], [], []) for key in models}
    turn = 0
    for scene in scenes:
        features = {key: m.encode_scene(scene.lidar, scene.radar) for key, m in models.items()}
        for prompt in scene.prompts:
            keys = list(models) if turn % 2 == 0 else list(models)[::-1]
            for key in keys:
                model, spec, calls = models[key], specs[key], out[key]
                for cached in (True, False) if turn % 2 == 0 else (False, True):
                    if cached:
                        calls.cached.append(
                            _timed_ground(model, spec, features[key], prompt, device)
                        )
                    else:
                        calls.fresh.append(_timed_fresh(model, spec, scene, prompt, device))
                calls.repeated.append(_timed_repeated(model, spec, features[key], prompt, device))
            turn += 1
    return out


def _timed_ground(
    model: TPCNet, spec: PathSpec, features: SceneFeatures, prompt: str, device: str
) -> Call:
    synchronize(device)
    t0 = time.perf_counter()
    pred = model.ground(features, prompt)
    synchronize(device)
    wall = (time.perf_counter() - t0) * 1000.0
    stages = {k: float(getattr(pred.timings, k)) for k in spec.ground_stages}
    return Call(wall, stages, len(pred.boxes), _answer(model, pred.scores))


def _timed_fresh(
    model: TPCNet, spec: PathSpec, scene: SceneWorkload, prompt: str, device: str
) -> Call:
    synchronize(device)
    t0 = time.perf_counter()
    new = model.encode_scene(scene.lidar, scene.radar)
    pred = model.ground(new, prompt)
    synchronize(device)
    wall = (time.perf_counter() - t0) * 1000.0
    stages = {k: float(getattr(new.timings, k)) for k in spec.scene_stages}
    stages.update({k: float(getattr(pred.timings, k)) for k in spec.ground_stages})
    return Call(wall, stages, len(pred.boxes), _answer(model, pred.scores))


def _timed_repeated(
    model: TPCNet, spec: PathSpec, features: SceneFeatures, prompt: str, device: str
) -> Call:
    # A variant of the prompt, encoded once and then served from the text cache (the measured
    # prompt itself stays new to the encoder for the other timings).
    seen = f"{prompt} again"
    old = text_cache(model, 1)
    try:
        model.ground(features, seen)
        return _timed_ground(model, spec, features, seen, device)
    finally:
        text_cache(model, old)


def _lap(device: str, t0: float) -> float:
    synchronize(device)
    return (time.perf_counter() - t0) * 1000.0


def measure_outside_tpcnet(
    model: TPCNet, scenes: list[SceneWorkload], device: str, limit: int
) -> dict[str, list[float]]:
    """The TPCNet path's ``ground`` stages timed from outside the model, through its public
    submodules (``text_encoder``, ``grounding.text_fusion``, ``scene.neck``, ``scene.head``,
    :func:`decode`)."""
    out: dict[str, list[float]] = {k: [] for k in GROUND_STAGES}
    features: dict[int, SceneFeatures] = {}
    for scene, prompt in prompt_pairs(scenes)[:limit]:
        if scene.world_index not in features:
            features[scene.world_index] = model.encode_scene(scene.lidar, scene.radar)
        stages = features[scene.world_index].stages
        with torch.no_grad():
            synchronize(device)
            t0 = time.perf_counter()
            text = model.text_encoder([prompt])
            out["text"].append(_lap(device, t0))
            t0 = time.perf_counter()
            conditioned = [
                fuse(lr, text.tokens, text.padding_mask)
                for fuse, lr in zip(model.grounding.text_fusion, stages, strict=True)
            ]
            out["dggf"].append(_lap(device, t0))
            t0 = time.perf_counter()
            neck = model.scene.neck(conditioned)
            out["neck"].append(_lap(device, t0))
            t0 = time.perf_counter()
            head = model.scene.head(neck)
            out["head"].append(_lap(device, t0))
            t0 = time.perf_counter()
            decode(head, model.head_grid, model.cfg.head)
            torch.sigmoid(head.heatmap[0]).float().cpu().numpy()
            out["decode"].append(_lap(device, t0))
    return out


def measure_outside_referent(
    model: TPCNet, scenes: list[SceneWorkload], device: str, limit: int
) -> dict[str, list[float]]:
    """The referent path's ``ground`` stages timed from outside the model: ``text`` (the model's
    ``text_encoder``), ``referent`` (the referent head's ``refer`` on the scene's ``features.objects``, sigmoid
    to numpy) and ``decode`` (ranking and :func:`model.referent.heatmap.referent_heatmap`)."""
    out: dict[str, list[float]] = {k: [] for k in REFERENT.ground_stages}
    features: dict[int, SceneFeatures] = {}
    for scene, prompt in prompt_pairs(scenes)[:limit]:
        if scene.world_index not in features:
            features[scene.world_index] = model.encode_scene(scene.lidar, scene.radar)
        f = features[scene.world_index]
        objects = f.objects
        assert objects is not None and f.detection_heatmaps is not None
        with torch.no_grad():
            synchronize(device)
            t0 = time.perf_counter()
            text = model.text_encoder([prompt])
            out["text"].append(_lap(device, t0))
            t0 = time.perf_counter()
            if len(objects):
                probs = torch.sigmoid(referent_head(model).refer(objects, text)[0])
                probs = probs.float().cpu().numpy()
            else:
                probs = np.zeros(0, dtype=np.float32)
            out["referent"].append(_lap(device, t0))
        t0 = time.perf_counter()
        probs = probs.astype(np.float64)
        np.argsort(-probs, kind="stable")
        referent_heatmap(
            f.detection_heatmaps,
            objects.boxes,
            objects.labels,
            probs,
            model.head_grid,
            model.cfg.head.anchor,
        )
        out["decode"].append(_lap(device, t0))
    return out


def measure_detect_parts(
    model: TPCNet, scenes: list[SceneWorkload], device: str
) -> tuple[dict[str, list[float]], list[float], list[int]]:
    """The referent path's ``detect`` stage of ``encode_scene`` part by part, from outside: the
    sensor branches and fusion (:func:`bench.perf.model_parts.model_parts`), then the ``neck``, the
    ``head``, the decoding at the candidate threshold and the candidates' description. Returns
    the parts' times, the model's own ``SceneTimings.detect`` of the same scenes, and the
    candidates per scene."""
    out: dict[str, list[float]] = {k: [] for k in DETECT_PARTS}
    reported, counts = [], []
    parts = model_parts(model)
    limit = model.cfg.referent.max_candidates
    for scene in scenes:
        reported.append(float(model.encode_scene(scene.lidar, scene.radar).timings.detect))
        with torch.no_grad():
            lidar = as_points(scene.lidar, 4, "lidar").to(model.device)
            radar = as_points(scene.radar, 7, "radar").to(model.device)
            stages, lidar_stage, radar_stage = parts.sensors(lidar, radar)
            synchronize(device)
            t0 = time.perf_counter()
            neck = parts.neck(stages)
            out["neck"].append(_lap(device, t0))
            t0 = time.perf_counter()
            head = parts.head(neck)
            out["head"].append(_lap(device, t0))
            t0 = time.perf_counter()
            dets = parts.proposals(head)
            torch.sigmoid(head.heatmap[0]).float().cpu().numpy()
            out["decode"].append(_lap(device, t0))
            t0 = time.perf_counter()
            objects = parts.describe(
                *keep_candidates(dets, limit),
                parts.maps(neck, lidar_stage, radar_stage),
                lidar.cpu().numpy(),
                radar.cpu().numpy(),
            )
            out["candidates"].append(_lap(device, t0))
            counts.append(len(objects))
    return out, reported, counts


def compare_threads(
    model: TPCNet, scenes: list[SceneWorkload], limit: int
) -> dict[str, dict[int, list[float]]]:
    """``ground`` and ``encode_scene`` + ``ground`` with 1 torch thread and with one per core,
    alternating per prompt (text cache off); the thread count is restored afterwards. Empty on a
    one-core machine."""
    old = torch.get_num_threads()
    counts = sorted({1, os.cpu_count() or 1})
    if len(counts) == 1:
        return {}
    ground: dict[int, list[float]] = {t: [] for t in counts}
    total: dict[int, list[float]] = {t: [] for t in counts}
    cache = text_cache(model, 0)
    try:
        for i, (scene, prompt) in enumerate(prompt_pairs(scenes)[:limit]):
            for t in counts if i % 2 == 0 else counts[::-1]:
                torch.set_num_threads(t)
                t0 = time.perf_counter()
                features = model.encode_scene(scene.lidar, scene.radar)
                t1 = time.perf_counter()
                model.ground(features, prompt)
                t2 = time.perf_counter()
                ground[t].append((t2 - t1) * 1000.0)
                total[t].append((t2 - t0) * 1000.0)
    finally:
        torch.set_num_threads(old)
        text_cache(model, cache)
    return {"ground_ms": ground, "encode_ground_ms": total}


@dataclass(frozen=True)
class ProfileRow:
    """One function of a cProfile: where, calls, self and cumulative milliseconds per call of the
    profiled function."""

    where: str
    calls: float
    self_ms: float
    cumulative_ms: float


def profile_calls(fn: Callable[[], object], calls: int, top: int = 12) -> list[ProfileRow]:
    """cProfile of ``calls`` calls of ``fn``: the ``top`` functions with the most self time."""
    profiler = cProfile.Profile()
    profiler.enable()
    for _ in range(calls):
        fn()
    profiler.disable()
    stats = pstats.Stats(profiler)
    entries = sorted(stats.stats.items(), key=lambda kv: kv[1][2], reverse=True)  # type: ignore[attr-defined]
    rows = []
    for (file, line, name), (_, ncalls, tottime, cumtime, _) in entries[:top]:
        where = name if file == "~" else f"{Path(file).name}:{line} {name}"
        rows.append(
            ProfileRow(where, ncalls / calls, tottime * 1000.0 / calls, cumtime * 1000.0 / calls)
        )
    return rows


def profile_path(
    model: TPCNet, scene: SceneWorkload, ground_calls: int, encode_calls: int
) -> tuple[list[ProfileRow], list[ProfileRow]]:
    """cProfile of ``ground`` on a cached scene (every prompt new to the text cache) and of
    ``encode_scene``."""
    features = model.encode_scene(scene.lidar, scene.radar)
    old = text_cache(model, 0)
    prompts = list(scene.prompts)
    counter = iter(range(10**6))

    def ground_once() -> None:
        i = next(counter)
        model.ground(features, f"{prompts[i % len(prompts)]} ({i})")

    try:
        ground = profile_calls(ground_once, ground_calls)
    finally:
        text_cache(model, old)
    encode = profile_calls(lambda: model.encode_scene(scene.lidar, scene.radar), encode_calls)
    return ground, encode
