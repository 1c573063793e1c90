"""Per-prompt latency of the app's path, both grounding paths: ``python -m bench.perf.latency [--quick]``.

What the app does for a typed prompt, on scenes and prompts from the synthetic generator
(64-beam LiDAR and 5-scan radar with realistic point counts; prompts from
:func:`scenes.language.prompts.generate_prompts` over each world's sensed actors):

1. *cached scene*: ``model.ground(features, prompt)`` on a scene encoded beforehand;
2. *new scene*: ``model.encode_scene(lidar, radar)`` followed by ``model.ground``;
3. *prompt seen before*: ``ground`` of a prompt already in the text encoder's cache.

Every prompt of 1 and 2 is new to the text encoder (its per-prompt cache is switched off while
timing, as for a prompt the user has just typed). Both grounding paths (``ModelConfig.grounding``)
are measured in the same run, taking turns prompt by prompt so that both see the same load:

- the *referent path* (``"referent"``): ``encode_scene`` also runs the text-agnostic detector and
  describes its candidates (``SceneTimings.detect``); ``ground`` runs the text encoder and the
  referent transformer over the candidates (``GroundTimings.referent``) and draws the answer's
  heatmap (``GroundTimings.decode``). Model: ``checkpoints/tpcnet-small.pt`` when its grounding is
  ``referent``, else an untrained ``build_model("small", grounding="referent")`` (seed 0);
- the *TPCNet path* (``"tpcnet"``, the paper's DGGF + C3D-RECHead ranking): model
  ``checkpoints/tpcnet-small-faithful.pt``.

The result says which models were used. The stage breakdown comes from the models' own
:class:`model.core.features.GroundTimings`/``SceneTimings`` and is checked by timing the same stages from
outside through public submodules (TPCNet path: ``text_encoder``, ``text_fusion``, ``neck``,
``head``, :func:`model.head.detector.decode.decode`; referent path: ``text_encoder``, ``model.refer`` on
``features.objects``, :func:`model.referent.heatmap.referent_heatmap`, and the ``detect`` stage part by
part). The referent path is profiled (cProfile) in every run, the TPCNet path when it misses a
target. With CUDA, the ``paper`` preset (untrained) of both paths is measured on the GPU as well.

An untrained detection head puts ~0.1 everywhere on its heatmap, so hundreds of peaks reach
decoding and rotated NMS: decoding (the TPCNet path's ``decode``, the referent path's ``detect``)
is then much slower than with trained weights.

Layout: measurements in :mod:`bench.perf.latency_measure`, tables in :mod:`bench.perf.latency_report`, the
workload from :func:`bench.workloads.synthetic_scenes`.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import asdict

import torch

from bench.common import bench_main, bench_parser
from bench.measure import summarize
from bench.perf.latency_measure import (
    DETECT_NAMES,
    PATHS,
    REFERENT,
    LoadedModel,
    PathCalls,
    PathSpec,
    compare_threads,
    load_path_model,
    measure_detect_parts,
    measure_outside_referent,
    measure_outside_tpcnet,
    measure_paths,
    profile_path,
    text_cache,
)
from bench.perf.latency_report import (
    calls_data,
    check_table,
    detect_table,
    latency_table,
    median,
    profile_table,
    side_by_side_table,
    stage_table,
    targets,
    threads_table,
)
from bench.report import BenchResult, Table, Target, fmt_ms, fmt_ratio, machine_info
from bench.workloads import SceneWorkload, synthetic_scenes, warm_up


def workload(quick: bool) -> list[SceneWorkload]:
    """Synthetic scenes (seed 0, 6 prompts per world) until 10 (``quick``) or 60 prompts."""
    needed = 10 if quick else 60
    scenes: list[SceneWorkload] = []
    world = 0
    while sum(len(s.prompts) for s in scenes) < needed and world < 200:
        scenes += synthetic_scenes(2, prompts_per_world=6, seed=0, first_world=world)
        world += 2
    return scenes


def measure_block(
    specs: dict[str, PathSpec],
    loaded: dict[str, LoadedModel],
    scenes: list[SceneWorkload],
    device: str,
    where: str,
    outside: int,
) -> tuple[list[Table], dict, dict[str, PathCalls]]:
    """Both paths on one device: the side-by-side table, each path's latency and stage tables and
    (``outside`` > 0) the check from outside on that many prompts; the raw data; the calls."""
    models = {key: v.model for key, v in loaded.items()}
    old = {key: text_cache(m, 0) for key, m in models.items()}
    try:
        calls = measure_paths(models, specs, scenes, device)
        checks: dict[str, dict[str, list[float]]] = {}
        if outside:
            for key, model in models.items():
                measure = measure_outside_referent if key == "referent" else measure_outside_tpcnet
                checks[key] = measure(model, scenes, device, outside)
    finally:
        for key, m in models.items():
            text_cache(m, old[key])
    short = {key: v.short for key, v in loaded.items()}
    tables = [side_by_side_table(f"Both paths, {where}", list(specs.values()), calls, short)]
    data: dict = {}
    for key, spec in specs.items():
        c = calls[key]
        tables += [
            latency_table(f"Per-prompt latency, {spec.label}, {where}", c),
            stage_table(
                f"`ground` by stage, {spec.label}, {where}",
                c.cached,
                spec.ground_stages,
                spec.stage_names,
            ),
            stage_table(
                f"`encode_scene` + `ground` by stage, {spec.label}, {where}",
                c.fresh,
                spec.scene_stages + spec.ground_stages,
                spec.stage_names,
            ),
        ]
        data[key] = {"model": loaded[key].note, **calls_data(spec, c)}
        if key in checks:
            how = (
                "`model.text_encoder`, `model.refer` on `features.objects` (sigmoid to numpy) "
                "and the ranking with `model.referent.heatmap.referent_heatmap`, called one by one"
                if key == "referent"
                else "the same stages called one by one through the model's public submodules"
            )
            tables.append(
                check_table(
                    f"Check of the stage timings, {spec.label}, {where}",
                    c.cached,
                    checks[key],
                    spec.stage_names,
                    how,
                )
            )
            data[key]["outside_stages_ms"] = checks[key]
    return tables, data, calls


def _path_findings(spec: PathSpec, calls: PathCalls, loaded: LoadedModel) -> list[str]:
    model, note = loaded.model, loaded.note
    out = []
    cached = calls.cached
    boxes = sum(c.boxes for c in cached) / len(cached)
    answer = sum(c.answer for c in cached) / len(cached)
    out.append(
        f"{spec.label}: {note}; {boxes:.1f} boxes per prompt returned, {answer:.1f} at the "
        "operating threshold."
    )
    text = summarize([c.stages["text"] for c in cached]).median
    out.append(
        f"{spec.label}: the text encoder (MiniLM, a prompt never seen) takes {fmt_ms(text)} ms of "
        f"the {fmt_ms(median(cached))} ms median `ground`; a prompt seen before takes "
        f"{fmt_ms(median(calls.repeated))} ms."
    )
    if spec.key == "tpcnet":
        rest = summarize([c.wall_ms - c.stages["decode"] for c in cached]).median
        out.append(
            f"{spec.label}: `ground` without decoding (text encoder, DGGF, neck, head and "
            f"overhead): median {fmt_ms(rest)} ms; decoding's share depends on how many heatmap "
            "peaks pass the score threshold, i.e. on the weights."
        )
    elif not loaded.trained:
        out.append(
            f"{spec.label}: with an untrained detection head (~0.1 everywhere) up to `top_k` = "
            f"{model.cfg.head.top_k} heatmap peaks pass the candidate threshold "
            f"{model.cfg.referent.candidate_threshold} and go through rotated NMS inside "
            "`encode_scene` (the table of its detection stage); a trained head leaves a few dozen."
        )
    return out


def _referent_miss_notes(missed: set[str], trained: bool) -> list[str]:
    """What the tables say about a missed referent-path target, and what would fix it."""
    out = []
    if any(n.startswith("Referent path: `ground`") for n in missed):
        out.append(
            "Referent path, `ground` missed: most of it is the frozen MiniLM pass for a prompt "
            "never seen (the stage table; a prompt seen before costs only the referent "
            "transformer and the heatmap), which no change in the referent stage removes; the "
            "referent transformer (3 decoder layers over at most 40 candidates) costs its "
            "module-call overhead more than its FLOPs. Timings of this run are pessimistic when "
            "the load average at the start exceeds the core count."
        )
    if any(n.startswith("Referent path: `encode_scene`") for n in missed):
        untrained = (
            " With this untrained head every one of the `top_k` peaks reaches rotated NMS, which "
            "calls the exact polygon IoU once per kept box: most of the detection stage."
            if not trained
            else ""
        )
        out.append(
            "Referent path, `encode_scene` + `ground` missed: the scene half (pillars, "
            "backbones, BACA) is the TPCNet path's, plus the detection stage (its own table)."
            + untrained
            + " Same boxes in less time: stop each class's NMS once `max_detections` boxes are "
            "kept (only that many survive the final cut), or compute the IoUs of all nearby "
            "pairs in one vectorised call."
        )
    return out


def _threads_finding(label: str, data: dict, load: float) -> str:
    ground = data["ground_ms"]
    one, many = min(ground), max(ground)
    ratio = summarize(ground[many]).median / summarize(ground[one]).median
    return (
        f"{label}: with {many} torch threads `ground` took {fmt_ratio(ratio)} the time it takes "
        f"with {one} (medians, same prompts, alternating; load average {load:.1f} at the start): "
        "when the cores are shared, torch's OpenMP threads wait for each other at every "
        "operation, which is why the app runs with 1 thread."
    )


def run(quick: bool = False, command: str = "python -m bench.perf.latency") -> BenchResult:
    """Measure the latency of both paths (see the module docstring)."""
    start = time.perf_counter()
    machine = machine_info(command)
    scenes = workload(quick)
    n_prompts = sum(len(s.prompts) for s in scenes)
    lidar_pts = [len(s.lidar) for s in scenes]
    radar_pts = [len(s.radar) for s in scenes]
    specs = {s.key: s for s in PATHS}
    loaded = {key: load_path_model(spec, "small", "cpu") for key, spec in specs.items()}
    models = {key: v.model for key, v in loaded.items()}
    for model in models.values():
        warm_up(model, scenes[0].lidar, scenes[0].radar)

    where = "`small` preset, CPU"
    tables, paths_data, calls = measure_block(
        specs, loaded, scenes, "cpu", where, 5 if quick else 20
    )
    all_targets: list[Target] = []
    for key, spec in specs.items():
        all_targets += targets(spec, calls[key], "small, CPU")
    findings = [t.describe() for t in all_targets]
    for key, spec in specs.items():
        findings += _path_findings(spec, calls[key], loaded[key])

    referent = models["referent"]
    parts, reported, counts = measure_detect_parts(referent, scenes, "cpu")
    tables.append(
        detect_table(
            f"`encode_scene`'s detection stage, {REFERENT.label}, {where}",
            parts,
            reported,
            DETECT_NAMES,
        )
    )
    share = sum(parts["decode"]) / max(sum(sum(v) for v in parts.values()), 1e-9)
    findings.append(
        f"{REFERENT.label}: {summarize(counts).median:.0f} candidates per scene (median; at most "
        f"{referent.cfg.referent.max_candidates}); decoding (peaks, rotated NMS) is "
        f"{100 * share:.0f} % of the detection stage timed part by part (all scenes); "
        f"`encode_scene` reports a median of {fmt_ms(summarize(reported).median)} ms for it."
    )
    data: dict = {
        "prompts": n_prompts,
        "worlds": [s.world_index for s in scenes],
        "lidar_points": lidar_pts,
        "radar_points": radar_pts,
        "paths": paths_data,
        "referent_detect": {"parts_ms": parts, "reported_ms": reported, "candidates": counts},
        "targets": [asdict(t) for t in all_targets],
        "threads": {},
    }

    findings.append(
        f"Threads: {torch.get_num_threads()} (`--threads`; the app's default is 1); the thread "
        "tables compare one thread per core."
    )
    for key, spec in specs.items():
        threads = compare_threads(models[key], scenes, 2 if quick else 8)
        if threads:
            data["threads"][key] = threads
            tables.append(threads_table(f"Torch intra-op threads, {spec.label}, {where}", threads))
            findings.append(_threads_finding(spec.label, threads, machine.load_average[0]))

    missed = {t.name for t in all_targets if not t.met}
    findings += _referent_miss_notes(missed, loaded["referent"].trained)
    for key, spec in specs.items():
        if key != "referent" and not any(spec.label in name for name in missed):
            continue
        ground, encode = profile_path(models[key], scenes[0], 5 if quick else 10, 3 if quick else 5)
        tables += [
            profile_table(
                f"Profile: `ground` on a cached scene, {spec.label} (cProfile, top self time)",
                ground,
            ),
            profile_table(
                f"Profile: `encode_scene`, {spec.label} (cProfile, top self time)", encode
            ),
        ]

    if torch.cuda.is_available():
        gpu = {key: load_path_model(spec, "paper", "cuda") for key, spec in specs.items()}
        for v in gpu.values():
            warm_up(v.model, scenes[0].lidar, scenes[0].radar)
        gpu_tables, data["paper_gpu"], _ = measure_block(
            specs,
            gpu,
            scenes,
            "cuda",
            "`paper` preset, GPU",
            0,
        )
        tables += gpu_tables
        findings.append("GPU models: " + "; ".join(f"{k}: {v.note}" for k, v in gpu.items()) + ".")
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


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.perf.latency``'s parser (the shared flags only)."""
    return bench_parser("bench.perf.latency", __doc__.splitlines()[0])


def main(argv: list[str] | None = None) -> int:
    return bench_main("bench.perf.latency", run, argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    raise SystemExit(main())
