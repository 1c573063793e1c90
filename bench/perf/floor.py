"""Time against the FLOP floor on real-size frames: ``python -m bench.floor [--quick]``.

How close ``encode_scene`` and ``ground`` run to what this machine's arithmetic allows (issue
20). Each timed call is set beside its *floor*: its FLOPs (``torch.utils.flop_counter``) divided
by the machine's rate, the GFLOP/s of a dense ``1024 x 1024`` float32 matmul measured just before
that call in the same run (:mod:`bench.perf.floor_measure`). The ratio ``time / floor`` is reported
for the whole call and for every stage (a stage without FLOPs, such as decoding, has no floor:
its time is all overhead and counts against its call's ratio).

Workload: real-size View-of-Delft frames (:mod:`bench.perf.vod_frames`: 167k-189k LiDAR points of a
full spin, 240-350 radar points of a single scan, written in the VoD layout and read back), the
shipped checkpoint ``checkpoints/tpcnet-small.pt`` (the referent path), ``ground`` of prompts new
to the text encoder (its cache off) on the scene just encoded. Default 2 torch threads (one per
core of the 2-core machine of issue 20). Targets: ``encode_scene`` median ratio <= 2.0,
``ground`` <= 4.0.

Options (beside ``--quick``, ``--threads``, ``--out-dir`` of every benchmark): ``--frames N``,
``--repeats R``, ``--prompts P`` (per frame), ``--name`` (results file stem, default ``floor``;
``<name>_baseline`` keeps a run of older code), ``--baseline-package DIR`` with
``--baseline-checkpoint PATH`` (older code measured in the same run, on a checkpoint it can read;
``--baseline-commit REV`` names its commit in the report, and :data:`MAKE_BASELINE` makes it)
and ``--baseline PATH`` (a previous result shown
beside this one; default ``bench/results/<name>_baseline.json`` where it exists). The section
``floor_1thread`` is the same benchmark with ``--threads 1 --name floor_1thread``.
"""

from __future__ import annotations

import argparse
import importlib
import math
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from bench.common import bench_main, bench_parser
from bench.measure import summarize
from bench.perf.floor_measure import (
    ENCODE_STAGES,
    GROUND_STAGES,
    MATMUL_N,
    FloorRun,
    TimedCall,
    measure,
)
from bench.perf.latency_measure import CHECKPOINT, DETECT_NAMES, REFERENT, load_path_model
from bench.perf.vod_frames import LIDAR_POINTS, RADAR_POINTS, vod_frames
from bench.report import (
    RESULTS_DIR,
    BenchResult,
    Table,
    Target,
    fmt_ms,
    fmt_ratio,
    machine_info,
    read_result,
)
from bench.workloads import warm_up
from model import TPCNet
from scenes.utils.cli import option

ENCODE_TARGET = 2.0
GROUND_TARGET = 4.0
BASELINE_SUFFIX = "_baseline"
"""``--name X_baseline`` keeps a run of older code; a run named ``X`` shows
``bench/results/X_baseline.json`` beside itself where it exists."""
STAGE_NAMES = REFERENT.stage_names
KIND_NAMES = {"encode": "`encode_scene`", "ground": "`ground`, new prompt"}


def _median(values: list[float]) -> float:
    values = [v for v in values if not math.isnan(v)]
    return summarize(values).median if values else float("nan")


def summary(run: FloorRun) -> dict:
    """Medians of the run (what the tables show and a later run compares with)."""
    peak = max(c.rate for c in run.calls)
    out: dict = {"rate_gflops": _median([c.rate for c in run.calls]), "peak_gflops": peak}
    for kind, stages in (("encode", ENCODE_STAGES), ("ground", GROUND_STAGES)):
        calls = run.of(kind)
        walls = summarize([c.wall_ms for c in calls])
        entry = {
            "calls": len(calls),
            "gflop": _median([c.flops["total"] / 1e9 for c in calls]),
            "floor_ms": _median([c.floor_ms() for c in calls]),
            "median_ms": walls.median,
            "p90_ms": walls.p90,
            "ratio": _median([c.ratio() for c in calls]),
            "best_ratio": min(c.wall_ms / (c.flops["total"] / (peak * 1e9) * 1e3) for c in calls),
            "stages": {},
        }
        for s in stages:
            entry["stages"][s] = {
                "gflop": _median([c.flops.get(s, 0) / 1e9 for c in calls]),
                "median_ms": _median([c.stages[s] for c in calls]),
                "ratio": _median([c.ratio(s) for c in calls]),
            }
        out[kind] = entry
    rate = _median(run.detect_rates)
    enc = run.of("encode")
    parts = {}
    for part, times in run.detect_parts.items():
        flops = _median([c.flops.get(part, 0) for c in enc])
        ms = _median(times)
        floor = flops / (rate * 1e9) * 1e3
        parts[part] = {
            "gflop": flops / 1e9,
            "median_ms": ms,
            "ratio": ms / floor if floor > 0 else float("nan"),
        }
    out["detect_parts"] = parts
    return out


def _ratio_cell(x: float) -> str:
    return "no FLOPs" if math.isnan(x) else fmt_ratio(x)


def ratio_table(s: dict, baseline: dict | None) -> Table:
    """The two calls against their floors and targets."""
    rows = []
    for kind, target in (("encode", ENCODE_TARGET), ("ground", GROUND_TARGET)):
        e = s[kind]
        row = [
            KIND_NAMES[kind],
            str(e["calls"]),
            f"{e['gflop']:.3g}",
            fmt_ms(e["floor_ms"]),
            fmt_ms(e["median_ms"]),
            fmt_ms(e["p90_ms"]),
            f"**{fmt_ratio(e['ratio'])}**",
            f"<= {target:g}x",
            fmt_ratio(e["best_ratio"]),
        ]
        if baseline is not None:
            row.insert(8, fmt_ratio(baseline[kind].get("best_ratio", float("nan"))))
            row.insert(6, fmt_ratio(baseline[kind]["ratio"]))
            row.insert(4, fmt_ms(baseline[kind]["median_ms"]))
        rows.append(tuple(row))
    cols = ["call", "calls", "GFLOP", "floor ms", "median ms", "p90 ms", "ratio", "target"]
    cols.append("best ratio")
    if baseline is not None:
        cols = [
            "call", "calls", "GFLOP", "floor ms", "baseline median ms", "median ms", "p90 ms",
            "baseline ratio", "ratio", "target", "baseline best ratio", "best ratio",
        ]  # fmt: skip
    notes = [
        f"Floor: the call's FLOPs at the machine rate, a {MATMUL_N} x {MATMUL_N} float32 matmul "
        f"measured before each call (median over this run's calls: {s['rate_gflops']:.0f} "
        "GFLOP/s); ratio: median over calls of time / floor (the issue's measure); best "
        "ratio: the fastest call's time against its floor at the run's fastest matmul "
        f"({s['peak_gflops']:.0f} GFLOP/s), what the code does when the cores are its own.",
    ]
    if baseline is not None:
        notes.append(
            f"Baseline: the same command on older code (its run: "
            f"{baseline['rate_gflops']:.0f} GFLOP/s median rate); ratios are comparable across "
            "runs, times only as far as the machine's load was alike."
        )
    return Table("Time against the FLOP floor", tuple(cols), tuple(rows), tuple(notes))


def stage_table(
    title: str, stages: dict, baseline: dict | None, note: str, names: dict[str, str]
) -> Table:
    """One call's stages: FLOPs, median time and ratio (beside the baseline's)."""
    rows = []
    for name, e in stages.items():
        row = [names.get(name, name), f"{e['gflop']:.3g}", fmt_ms(e["median_ms"])]
        row.append(_ratio_cell(e["ratio"]))
        if baseline is not None:
            b = baseline.get(name)
            row[2:2] = [fmt_ms(b["median_ms"]) if b else ""]
            row[4:4] = [_ratio_cell(b["ratio"]) if b else ""]
        rows.append(tuple(row))
    cols = ["stage", "GFLOP", "median ms", "ratio"]
    if baseline is not None:
        cols = ["stage", "GFLOP", "baseline median ms", "median ms", "baseline ratio", "ratio"]
    return Table(title, tuple(cols), tuple(rows), (note,))


def _baseline(path: Path | None) -> tuple[dict | None, str | None]:
    if path is None or not path.is_file():
        return None, None
    result = read_result(path)
    return result.data.get("summary"), result.machine.command


def run(
    quick: bool = False,
    command: str = "python -m bench.floor",
    frames: int | None = None,
    repeats: int | None = None,
    prompts: int = 3,
    name: str = "floor",
    baseline: Path | None = None,
    baseline_package: Path | None = None,
    baseline_checkpoint: Path | None = None,
    baseline_commit: str | None = None,
) -> BenchResult:
    """Measure (see the module docstring)."""
    start = time.perf_counter()
    machine = machine_info(command)
    n_frames = frames or (2 if quick else 6)
    n_repeats = repeats or (2 if quick else 5)
    loaded = load_path_model(REFERENT, "small", "cpu")
    model = loaded.model
    models = {"now": model}
    if baseline_package is not None:
        old = load_baseline_package(baseline_package, baseline_checkpoint or CHECKPOINT)
        models = {"baseline": old, "now": model}
    with tempfile.TemporaryDirectory(prefix="floor-vod-") as tmp:
        chosen = vod_frames(Path(tmp), n_frames, prompts=max(prompts, 1))
    for m in models.values():
        warm_up(m, chosen[0].lidar, chosen[0].radar)
    runs = measure(models, chosen, n_repeats, prompts)
    measured = runs["now"]
    s = summary(measured)
    base_path = baseline if baseline is not None else RESULTS_DIR / f"{name}{BASELINE_SUFFIX}.json"
    is_baseline = name.endswith(BASELINE_SUFFIX)
    if "baseline" in runs:
        base, base_cmd = summary(runs["baseline"]), None
    else:
        base, base_cmd = (None, None) if is_baseline else _baseline(base_path)
    tables = [ratio_table(s, base)]
    detect_note = (
        "The model's own `SceneTimings`; detection: neck, head, decoding and candidate "
        "description (its parts in the next table)."
    )
    tables.append(
        stage_table(
            "`encode_scene` by stage",
            s["encode"]["stages"],
            base["encode"]["stages"] if base else None,
            detect_note,
            STAGE_NAMES,
        )
    )
    tables.append(
        stage_table(
            "`encode_scene`'s detection stage, part by part (timed from outside)",
            s["detect_parts"],
            base.get("detect_parts") if base else None,
            "Through the model's public submodules, one pass per round "
            "(`bench.perf.latency_measure.measure_detect_parts`); decoding and candidate description "
            "have no FLOPs: their time is overhead.",
            DETECT_NAMES,
        )
    )
    tables.append(
        stage_table(
            "`ground` of a new prompt by stage",
            s["ground"]["stages"],
            base["ground"]["stages"] if base else None,
            "The model's own `GroundTimings`; text: MiniLM (the prompt is new to it), referent: "
            "the referent stage over the scene's candidates, answer: ranking and heatmap.",
            STAGE_NAMES,
        )
    )
    targets = [
        Target(
            "`encode_scene` time / FLOP floor, real-size frames, CPU",
            s["encode"]["ratio"],
            ENCODE_TARGET,
            "x",
            False,
        ),
        Target(
            "`ground` (new prompt) time / FLOP floor, real-size frames, CPU",
            s["ground"]["ratio"],
            GROUND_TARGET,
            "x",
            False,
        ),
    ]
    n = machine.torch_threads
    threads = f"{n} thread{'' if n == 1 else 's'}"
    lidar = [len(f.lidar) for f in chosen]
    radar = [len(f.radar) for f in chosen]
    findings = [t.describe() for t in targets]
    findings += [
        f"Model: {loaded.note}; {_median([float(c) for c in measured.candidates]):.0f} "
        "candidates per scene (median).",
        f"Workload: {len(chosen)} frames (LiDAR {min(lidar)}-{max(lidar)} points, radar "
        f"{min(radar)}-{max(radar)}; the kept ranges are {LIDAR_POINTS} and {RADAR_POINTS}), "
        f"{n_repeats} rounds, {prompts} prompts per frame; {machine.torch_threads} torch threads.",
        "The machine's cores are shared with other jobs: each call's floor uses the matmul rate "
        "measured just before it, so the ratios hold under the load of that moment, the times "
        "less so (see the load average above).",
    ]
    if baseline_package is not None:
        findings.append(
            f"Baseline: an older copy of `model/`, measured in this run call by call beside "
            f"this checkout (package `model_base` under `{baseline_package}`, made as "
            f"`{MAKE_BASELINE}` with REV "
            + (f"{baseline_commit}" if baseline_commit else "the commit it stands for")
            + "), running "
            + (
                "the shipped checkpoint."
                if baseline_checkpoint is None
                else f"the checkpoint `{baseline_checkpoint}` (a checkpoint of the config that "
                "code knows; its sizes are the shipped one's, so its FLOPs are too)."
            )
        )
    elif base is not None:
        findings.append(f"Baseline ({base_path.name}): `{base_cmd}`.")
    data = {
        "summary": s,
        "baseline_summary": base,
        "frames": [f.sample_id for f in chosen],
        "lidar_points": lidar,
        "radar_points": radar,
        "calls": [_call_data(c) for c in measured.calls],
        "detect_parts_ms": measured.detect_parts,
        "detect_rates": measured.detect_rates,
        "targets": [vars(t) for t in targets],
    }
    return BenchResult(
        name=name,
        title=f"Time against the FLOP floor (real-size frames, {threads})",
        machine=machine,
        tables=tuple(tables),
        findings=tuple(findings),
        data=data,
        seconds=time.perf_counter() - start,
    )


MAKE_BASELINE = (
    "git archive REV model | tar -x -C DIR && mv DIR/model DIR/model_base && "
    "find DIR/model_base -name '*.py' -print0 | xargs -0 sed -i -E "
    "'s/^(\\s*)(from|import) model([. ])/\\1\\2 model_base\\3/' && "
    "sed -i -E 's/\"model\\./\"model_base./g' DIR/model_base/__init__.py"
)
"""How a baseline package is made from commit ``REV`` (every module's imports, and the package's
lazy-import table, renamed to ``model_base``)."""


def load_baseline_package(directory: Path, checkpoint: Path = CHECKPOINT) -> TPCNet:
    """``checkpoint`` (default: the shipped one) loaded by an older copy of ``model`` renamed
    ``model_base`` (its imports rewritten) under ``directory``, in eval mode, beside this
    repository's ``model``. An older copy may not know a newer checkpoint's config fields: give
    it a checkpoint of its own time (``--baseline-checkpoint``)."""
    if not (directory / "model_base" / "checkpoint.py").is_file():
        raise SystemExit(f"error: {directory}/model_base/checkpoint.py not found; make it with: "
                         f"{MAKE_BASELINE}")  # fmt: skip
    sys.path.insert(0, str(directory))
    module = importlib.import_module("model_base.checkpoint")
    return module.load_checkpoint(checkpoint).eval()


def _call_data(c: TimedCall) -> dict:
    return {
        "kind": c.kind,
        "frame": c.frame,
        "rate": c.rate,
        "wall_ms": c.wall_ms,
        "stages": c.stages,
        "flops": c.flops,
    }


@dataclass(frozen=True, kw_only=True)
class FloorOptions:
    """This benchmark's own flags (see the module docstring; :func:`run`'s keyword arguments)."""

    frames: int | None = option(None, help="frames (default 6, quick 2)")
    repeats: int | None = option(None, help="rounds (default 5, quick 2)")
    prompts: int = option(3, help="prompts per frame (default %(default)s)")
    name: str = option("floor", help="results file stem (default %(default)s)")
    baseline_package: Path | None = option(
        None,
        help="a folder holding an older copy of model/ as package model_base: measured in the "
        "same run, call by call beside this checkout",
    )
    baseline_checkpoint: Path | None = option(
        None,
        help="with --baseline-package: the checkpoint the older code runs (default: the shipped "
        "one; an older copy of model/ may not read a newer checkpoint's config)",
    )
    baseline_commit: str | None = option(
        None, help="with --baseline-package: the commit it was made from, for the report's note"
    )
    baseline: Path | None = option(
        None,
        help="a previous result to show beside (default bench/results/<name>_baseline.json)",
    )


FLOOR_THREADS = 2
"""``--threads``' default here: the floor is measured at two threads."""


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.floor``'s parser."""
    return bench_parser("bench.floor", __doc__.splitlines()[0], FloorOptions)


def main(argv: list[str] | None = None) -> int:
    return bench_main(
        "bench.floor",
        run,
        argv,
        __doc__.splitlines()[0],
        default_threads=FLOOR_THREADS,
        options=FloorOptions,
    )


if __name__ == "__main__":
    raise SystemExit(main())
