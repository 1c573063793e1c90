"""Per-prompt latency of the app's path: ``python -m bench.latency [--quick]``.

What the app does for a typed prompt, on scenes and prompts from the synthetic generator
(64-beam LiDAR and 5-scan radar with realistic point counts; prompts from
:func:`scenes.prompts.generate_prompts` over each world's sensed actors):

1. *cached scene*: ``model.ground(features, prompt)`` on a scene encoded beforehand;
2. *new scene*: ``model.encode_scene(lidar, radar)`` followed by ``model.ground``.

Every prompt is new to the text encoder (its per-prompt cache is switched off while timing, as for
a prompt the user has just typed); a third row shows a prompt seen before (cache hit), timed
right after the other two for each prompt. Latency is
the wall-clock time of the call; the stage breakdown comes from the model's own
:class:`model.tpcnet.GroundTimings`/``SceneTimings``, and is checked by timing the same stages
from outside through the model's public submodules (``text_encoder``, ``text_fusion``, ``neck``,
``head``, :func:`model.decode.decode`).

Model: ``checkpoints/tpcnet-small.pt`` when it exists, else an untrained ``small`` model (seed 0).
An untrained head puts ~0.1 everywhere on the heatmap, so hundreds of peaks reach decoding and
rotated NMS: decoding is then slower than with trained weights. The result says which was used.
With CUDA, the ``paper`` preset (untrained) is measured on the GPU as well.
"""

from __future__ import annotations

import cProfile
import os
import pstats
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import torch

from bench.common import (
    REPO,
    BenchResult,
    SceneWorkload,
    Table,
    Target,
    bench_main,
    fmt_ms,
    fmt_ratio,
    machine_info,
    summarize,
    synchronize,
    synthetic_scenes,
)
from model import build_model
from model.decode import decode
from model.tpcnet import SceneFeatures, TPCNet

CHECKPOINT = REPO / "checkpoints" / "tpcnet-small.pt"
GROUND_STAGES = ("text", "dggf", "neck", "head", "decode")
SCENE_STAGES = ("pillars", "backbone", "fusion")
STAGE_NAMES = {
    "text": "text encoder (MiniLM)",
    "dggf": "DGGF (3 stages)",
    "neck": "neck (FPN)",
    "head": "head (C3D-RECHead)",
    "decode": "decoding (peaks, NMS)",
    "pillars": "pillar encoders (both sensors)",
    "backbone": "backbones (both sensors)",
    "fusion": "fusion (BACA, 3 stages)",
}
GROUND_TARGET_MS = 50.0
ENCODE_GROUND_TARGET_MS = 300.0


@dataclass(frozen=True)
class Call:
    """One timed call: wall-clock milliseconds, the model's own stage times, boxes returned."""

    wall_ms: float
    stages: dict[str, float]
    boxes: int


def load_model(preset: str, device: str) -> tuple[TPCNet, str]:
    """The checkpoint model for ``small`` when it exists, else an untrained one (seed 0)."""
    if preset == "small" and CHECKPOINT.is_file():
        from model.checkpoint import load_checkpoint

        model = load_checkpoint(CHECKPOINT, device=device)
        meta = model.checkpoint_metadata
        step = meta.get("step", "?")
        return model, f"trained checkpoint `{CHECKPOINT.relative_to(REPO)}` (step {step})"
    torch.manual_seed(0)
    model = build_model(preset).to(device).eval()
    return model, f"untrained `{preset}` model (random initialisation, seed 0)"


def _text_cache(model: TPCNet, size: int) -> int:
    """Set the MiniLM prompt-cache size (0 = every prompt is encoded); returns the old size."""
    encoder = model.text_encoder
    old = int(getattr(encoder, "cache_size", 0))
    if hasattr(encoder, "cache_size"):
        encoder.cache_size = size
    return old


def _prompts(scenes: list[SceneWorkload]) -> list[tuple[SceneWorkload, str]]:
    return [(s, p) for s in scenes for p in s.prompts]


def measure_paths(
    model: TPCNet, scenes: list[SceneWorkload], device: str
) -> tuple[list[Call], list[Call], list[Call]]:
    """Per prompt, in alternating order: ``ground`` on the scene encoded beforehand (cached
    path) and ``encode_scene`` + ``ground`` (new-scene path), so that both see the same load;
    then ``ground`` of a prompt already in the text cache. The text cache must be off (size 0)."""
    cached, fresh, repeated = [], [], []
    for scene in scenes:
        features = model.encode_scene(scene.lidar, scene.radar)
        for prompt in scene.prompts:

            def run_cached(features: SceneFeatures = features, prompt: str = prompt) -> None:
                synchronize(device)
                t0 = time.perf_counter()
                pred = model.ground(features, prompt)
                synchronize(device)
                wall = (time.perf_counter() - t0) * 1000.0
                stages = {k: float(getattr(pred.timings, k)) for k in GROUND_STAGES}
                cached.append(Call(wall, stages, len(pred.boxes)))

            def run_fresh(scene: SceneWorkload = scene, prompt: str = prompt) -> None:
                synchronize(device)
                t0 = time.perf_counter()
                new = model.encode_scene(scene.lidar, scene.radar)
                pred = model.ground(new, prompt)
                synchronize(device)
                wall = (time.perf_counter() - t0) * 1000.0
                stages = {k: float(getattr(new.timings, k)) for k in SCENE_STAGES}
                stages.update({k: float(getattr(pred.timings, k)) for k in GROUND_STAGES})
                fresh.append(Call(wall, stages, len(pred.boxes)))

            def run_repeated(features: SceneFeatures = features, prompt: str = prompt) -> None:
                # A variant of the prompt, encoded once and then served from the text cache
                # (the measured prompt itself stays new to the encoder for the other timings).
                seen = f"{prompt} again"
                old = _text_cache(model, 1)
                model.ground(features, seen)
                synchronize(device)
                t0 = time.perf_counter()
                pred = model.ground(features, seen)
                synchronize(device)
                wall = (time.perf_counter() - t0) * 1000.0
                _text_cache(model, old)
                stages = {k: float(getattr(pred.timings, k)) for k in GROUND_STAGES}
                repeated.append(Call(wall, stages, len(pred.boxes)))

            order = (run_cached, run_fresh) if len(cached) % 2 == 0 else (run_fresh, run_cached)
            for fn in (*order, run_repeated):
                fn()
    return cached, fresh, repeated


def measure_outside(
    model: TPCNet, scenes: list[SceneWorkload], device: str, limit: int
) -> dict[str, list[float]]:
    """The ``ground`` stages timed from outside the model, through its public submodules."""
    out: dict[str, list[float]] = {k: [] for k in GROUND_STAGES}
    pairs = _prompts(scenes)[:limit]
    features = {}
    for scene, prompt in pairs:
        if scene.world_index not in features:
            features[scene.world_index] = model.encode_scene(scene.lidar, scene.radar)
        stages = features[scene.world_index].stages

        def lap(t0: float) -> float:
            synchronize(device)
            return (time.perf_counter() - t0) * 1000.0

        with torch.no_grad():
            synchronize(device)
            t0 = time.perf_counter()
            text = model.text_encoder([prompt])
            out["text"].append(lap(t0))
            t0 = time.perf_counter()
            conditioned = [
                fuse(lr, text.tokens, text.padding_mask)
                for fuse, lr in zip(model.text_fusion, stages, strict=True)
            ]
            out["dggf"].append(lap(t0))
            t0 = time.perf_counter()
            neck = model.neck(conditioned)
            out["neck"].append(lap(t0))
            t0 = time.perf_counter()
            head = model.head(neck)
            out["head"].append(lap(t0))
            t0 = time.perf_counter()
            decode(head, model.head_grid, model.cfg.head)
            torch.sigmoid(head.heatmap[0]).float().cpu().numpy()
            out["decode"].append(lap(t0))
    return out


def compare_threads(
    model: TPCNet, scenes: list[SceneWorkload], limit: int
) -> tuple[Table | None, dict]:
    """``ground`` and ``encode_scene`` + ``ground`` with 1 torch thread and with one per core,
    alternating per prompt; the thread count is restored afterwards."""
    old = torch.get_num_threads()
    counts = sorted({1, os.cpu_count() or 1})
    if len(counts) == 1:
        return None, {}
    ground: dict[int, list[float]] = {t: [] for t in counts}
    total: dict[int, list[float]] = {t: [] for t in counts}
    try:
        for i, (scene, prompt) in enumerate(_prompts(scenes)[:limit]):
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
    rows = tuple(
        (
            f"{t} thread{'s' if t > 1 else ''}",
            str(len(ground[t])),
            fmt_ms(summarize(ground[t]).median),
            fmt_ms(summarize(ground[t]).p90),
            fmt_ms(summarize(total[t]).median),
            fmt_ms(summarize(total[t]).p90),
        )
        for t in counts
    )
    table = Table(
        title="Torch intra-op threads, `small` preset, CPU",
        columns=(
            "torch threads",
            "prompts",
            "`ground` median ms",
            "`ground` p90 ms",
            "encode + ground median ms",
            "encode + ground p90 ms",
        ),
        rows=rows,
        notes=(
            "The two settings alternate prompt by prompt (text cache off), so both see the same "
            "machine load. The app runs with 1 thread (`launch.py --threads 1`).",
        ),
    )
    return table, {"ground_ms": ground, "encode_ground_ms": total}


def profile_calls(fn, calls: int, top: int = 12) -> Table:  # type: ignore[no-untyped-def]
    """cProfile of ``calls`` calls of ``fn``: the functions with the most self time."""
    profiler = cProfile.Profile()
    profiler.enable()
    for _ in range(calls):
        fn()
    profiler.disable()
    stats = pstats.Stats(profiler)
    rows = []
    entries = sorted(stats.stats.items(), key=lambda kv: kv[1][2], reverse=True)  # type: ignore[attr-defined]
    for (file, line, name), (_, ncalls, tottime, cumtime, _) in entries[:top]:
        where = name if file == "~" else f"{Path(file).name}:{line} {name}"
        rows.append(
            (
                where,
                f"{ncalls / calls:.0f}",
                fmt_ms(tottime * 1000.0 / calls),
                fmt_ms(cumtime * 1000.0 / calls),
            )
        )
    return Table(
        title="",
        columns=("function", "calls per call", "self ms per call", "cumulative ms per call"),
        rows=tuple(rows),
    )


def _summary_row(label: str, samples: list[float]) -> tuple[str, ...]:
    s = summarize(samples)
    return (label, str(s.n), fmt_ms(s.median), fmt_ms(s.p90), fmt_ms(s.mean), fmt_ms(s.max))


def _stage_table(title: str, calls: list[Call], stages: tuple[str, ...]) -> Table:
    total_mean = summarize([c.wall_ms for c in calls]).mean
    rows = []
    for k in stages:
        s = summarize([c.stages[k] for c in calls])
        share = 100.0 * s.mean / total_mean
        rows.append((STAGE_NAMES[k], fmt_ms(s.median), fmt_ms(s.p90), f"{share:.0f} %"))
    rest = [c.wall_ms - sum(c.stages[k] for k in stages) for c in calls]
    s = summarize(rest)
    rows.append(("other (input checks, result packing)", fmt_ms(s.median), fmt_ms(s.p90), ""))
    s = summarize([c.wall_ms for c in calls])
    rows.append(("**wall-clock total**", fmt_ms(s.median), fmt_ms(s.p90), "100 %"))
    return Table(
        title=title,
        columns=("stage", "median ms", "p90 ms", "share of mean"),
        rows=tuple(rows),
    )


def _device_block(
    model: TPCNet, scenes: list[SceneWorkload], device: str, label: str, check: bool
) -> tuple[list[Table], dict, list[Call], list[Call]]:
    """Tables and raw data of one model on one device (``check``: time the stages from outside
    too); returns the tables, the data, and the cached-scene and new-scene calls."""
    old = _text_cache(model, 0)
    cached, fresh, repeated = measure_paths(model, scenes, device)
    tables = [
        Table(
            title=f"Per-prompt latency, {label}",
            columns=("path", "prompts", "median ms", "p90 ms", "mean ms", "max ms"),
            rows=(
                _summary_row("`ground` on a cached scene", [c.wall_ms for c in cached]),
                _summary_row("`encode_scene` + `ground` (new scene)", [c.wall_ms for c in fresh]),
                _summary_row(
                    "`ground`, prompt seen before (text cache hit)", [c.wall_ms for c in repeated]
                ),
            ),
        ),
        _stage_table(f"`ground` by stage, {label}", cached, GROUND_STAGES),
        _stage_table(
            f"`encode_scene` + `ground` by stage, {label}", fresh, SCENE_STAGES + GROUND_STAGES
        ),
    ]
    data: dict = {
        "cached_ground_ms": [c.wall_ms for c in cached],
        "encode_ground_ms": [c.wall_ms for c in fresh],
        "cached_stages_ms": {k: [c.stages[k] for c in cached] for k in GROUND_STAGES},
        "encode_stages_ms": {k: [c.stages[k] for c in fresh] for k in SCENE_STAGES + GROUND_STAGES},
        "boxes_per_prompt": [c.boxes for c in cached],
        "repeated_ground_ms": [c.wall_ms for c in repeated],
    }
    if check:
        outside = measure_outside(model, scenes, device, limit=20)
        rows = []
        for k in GROUND_STAGES:
            mine = summarize(outside[k]).median
            theirs = summarize([c.stages[k] for c in cached]).median
            rows.append((STAGE_NAMES[k], fmt_ms(theirs), fmt_ms(mine), fmt_ms(mine - theirs)))
        tables.append(
            Table(
                title=f"Check of the stage timings, {label}",
                columns=(
                    "stage",
                    "reported by `ground` (median ms)",
                    "timed from outside (median ms)",
                    "difference ms",
                ),
                rows=tuple(rows),
                notes=(
                    f"Outside: the same stages called one by one through the model's public "
                    f"submodules on the first {len(outside['text'])} prompts.",
                ),
            )
        )
        data["outside_stages_ms"] = outside
    _text_cache(model, old)
    return tables, data, cached, fresh


def run(quick: bool = False, command: str = "python -m bench.latency") -> BenchResult:
    """Measure the latency (see the module docstring)."""
    start = time.perf_counter()
    machine = machine_info(command)
    needed = 10 if quick else 60
    scenes: list[SceneWorkload] = []
    world = 0
    while sum(len(s.prompts) for s in scenes) < needed and world < 200:
        scenes += synthetic_scenes(2, prompts_per_world=6, seed=0, first_world=world)
        world += 2
    n_prompts = sum(len(s.prompts) for s in scenes)
    lidar_pts = [len(s.lidar) for s in scenes]
    radar_pts = [len(s.radar) for s in scenes]

    model, model_note = load_model("small", "cpu")
    # Warm-up: loads MiniLM, first-call allocations; a prompt outside the measured set.
    warm = model.encode_scene(scenes[0].lidar, scenes[0].radar)
    model.ground(warm, "the car ahead of us (warm-up)")
    model.ground(warm, "the pedestrians on the left (warm-up)")

    tables, data_cpu, cached, fresh = _device_block(
        model, scenes, "cpu", "`small` preset, CPU", True
    )
    ground_median = summarize([c.wall_ms for c in cached]).median
    full_median = summarize([c.wall_ms for c in fresh]).median
    targets = [
        Target("`ground` median, small, CPU", ground_median, GROUND_TARGET_MS, "ms", False),
        Target(
            "`encode_scene` + `ground` median, small, CPU",
            full_median,
            ENCODE_GROUND_TARGET_MS,
            "ms",
            False,
        ),
    ]
    findings = [t.describe() for t in targets]
    findings.append(
        f"Threads: {torch.get_num_threads()} (`--threads`; the app's default is 1); the thread "
        "table compares one thread per core."
    )
    no_decode = summarize([c.wall_ms - c.stages["decode"] for c in cached]).median
    findings.append(
        f"`ground` without decoding (text encoder, DGGF, neck, head and overhead): median "
        f"{fmt_ms(no_decode)} ms; decoding's share depends on how many heatmap peaks pass the "
        "score threshold, i.e. on the weights."
    )
    mean_boxes = sum(c.boxes for c in cached) / len(cached)
    findings.append(
        f"Model: {model_note}; it returned {mean_boxes:.1f} boxes per prompt on average "
        f"(score threshold {model.cfg.head.score_threshold})."
    )
    data: dict = {
        "model": model_note,
        "prompts": n_prompts,
        "worlds": [s.world_index for s in scenes],
        "lidar_points": lidar_pts,
        "radar_points": radar_pts,
        "small_cpu": data_cpu,
        "targets": [asdict(t) for t in targets],
    }

    old = _text_cache(model, 0)
    table, data["threads"] = compare_threads(model, scenes, 2 if quick else 8)
    _text_cache(model, old)
    if table is not None:
        tables.insert(1, table)
        ground_by_threads = data["threads"]["ground_ms"]
        one, many = min(ground_by_threads), max(ground_by_threads)
        slowdown = (
            summarize(ground_by_threads[many]).median / summarize(ground_by_threads[one]).median
        )
        findings.append(
            f"With {many} torch threads `ground` took {fmt_ratio(slowdown)} the time it takes with "
            f"{one} (medians, same prompts, alternating; load average "
            f"{machine.load_average[0]:.1f} at the start): when the cores are shared, torch's "
            "OpenMP threads wait for each other at every operation, which is why the app runs "
            "with 1 thread."
        )

    if not all(t.met for t in targets):
        scene = scenes[0]
        features = model.encode_scene(scene.lidar, scene.radar)
        old = _text_cache(model, 0)
        counter = iter(range(10**6))
        prompts = list(scene.prompts)

        def ground_once() -> None:
            i = next(counter)
            model.ground(features, f"{prompts[i % len(prompts)]} ({i})")

        t = profile_calls(ground_once, 5 if quick else 10)
        tables.append(
            Table(
                title="Profile: `ground` on a cached scene (cProfile, top self time)",
                columns=t.columns,
                rows=t.rows,
            )
        )
        _text_cache(model, old)
        t = profile_calls(lambda: model.encode_scene(scene.lidar, scene.radar), 3 if quick else 5)
        tables.append(
            Table(
                title="Profile: `encode_scene` (cProfile, top self time)",
                columns=t.columns,
                rows=t.rows,
            )
        )

    if torch.cuda.is_available():
        gpu_model, gpu_note = load_model("paper", "cuda")
        warm = gpu_model.encode_scene(scenes[0].lidar, scenes[0].radar)
        gpu_model.ground(warm, "the car ahead of us (warm-up)")
        gpu_tables, data_gpu, _, _ = _device_block(
            gpu_model, scenes, "cuda", "`paper` preset, GPU", False
        )
        tables += gpu_tables
        data["paper_gpu"] = data_gpu
        findings.append(f"GPU model: {gpu_note}.")
    else:
        findings.append("No CUDA device on this machine: the `paper` preset on GPU was not run.")

    findings.append(
        f"Workload: {n_prompts} prompts over {len(scenes)} synthetic scenes (LiDAR "
        f"{min(lidar_pts)}-{max(lidar_pts)} points, radar {min(radar_pts)}-{max(radar_pts)} "
        "points, 5 scans); every timed prompt is new to the text encoder unless said otherwise."
    )
    return BenchResult(
        name="latency",
        title="Per-prompt latency (the app's path)",
        machine=machine,
        tables=tuple(tables),
        findings=tuple(findings),
        data=data,
        seconds=time.perf_counter() - start,
    )


def main(argv: list[str] | None = None) -> int:
    return bench_main("bench.latency", run, argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    raise SystemExit(main())
