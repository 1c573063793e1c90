"""Run every benchmark and regenerate ``docs/PERFORMANCE.md``: ``python -m bench.run_all``
(what ``make bench`` runs).

Each benchmark runs in its own process (``python -m`` its module of :data:`MODULES`, so that
one benchmark's allocations do not disturb the next one's timings and each table's command can be repeated as
is) and writes ``bench/results/<name>.json``; scene generation speed comes from
``bench/perf/bench_synth.py`` (``bench/results/synth.json``). ``docs/PERFORMANCE.md`` is then written
from those JSON files alone: a summary of the targets, then one section per benchmark headed by
the machine and the exact command that made it.

Options: ``--quick`` (smoke run: fewer repetitions, the largest quadratic cases skipped),
``--threads N`` (torch threads of every benchmark; default 1, as the app),
``--only NAME ...`` (run some benchmarks, keep the others' previous results), ``--no-run``
(only regenerate the document from the existing results).
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from bench.common import (
    PERFORMANCE_DOC,
    REPO,
    RESULTS_DIR,
    BenchResult,
    BenchResultError,
    Table,
    Target,
    machine_info,
    read_result,
)
from scenes.utils.cli import command_parser, from_args, option
from scenes.utils.durable import atomic_write_text
from scenes.utils.textfile import read_text_file

MODULES = {
    "latency": "bench.perf.latency",
    "floor": "bench.perf.floor",
    "fusion_cost": "bench.perf.fusion_cost",
    "graph_cost": "bench.perf.graph_cost",
    "model_size": "bench.perf.model_size",
    "train_throughput": "bench.perf.train_throughput",
    "soak": "bench.perf.soak",
    "sensor_shift": "bench.studies.sensor_shift",
}
"""Each benchmark's name and module (``python -m MODULE``), in the order of the document."""
BENCHMARKS = tuple(MODULES)
"""Benchmarks of this package, in the order of the document."""
MANUAL = ("floor_1thread", "eval_throughput", "eval_throughput_1thread")
"""Sections that come from their stored results only, run by hand with the command in their
section: the floor benchmark on one thread (``python -m bench.floor --threads 1 --name
floor_1thread``) and the evaluation throughput (it compares with an older checkout)."""

SYNTH = "synth"
SYNTH_SCRIPT = REPO / "bench" / "perf" / "bench_synth.py"
SYNTH_ARGS = {False: ("--worlds", "10", "--frames", "20"), True: ("--worlds", "2", "--frames", "4")}

MISS_NOTES: dict[str, str] = {
    "`ground` median": (
        "**`ground` on a cached scene.** The latency section's stage table, its check from "
        "outside the model and its cProfile say where the time goes: the frozen MiniLM pass "
        "for a prompt never seen before (nothing once the prompt is cached), DGGF (mostly its "
        "axial graph, which already runs as the gradient-free roll loop at inference; the "
        "graph section compares both forms), the head (the largest FLOP count of the `small` "
        "model: 3x3 convs on the "
        "80 x 80 head grid), and decoding. Decoding depends on the weights: an untrained head "
        "is ~0.1 everywhere, so hundreds of peaks pass the 0.1 threshold and rotated NMS (a "
        "Python loop with exact polygon IoU per nearby pair) dominates; the 'without decoding' "
        "finding is what remains with a trained checkpoint that leaves a handful of peaks. "
        "What would fix the rest: a cheaper head (1x1 convs in the regression branches after "
        "the shared 3x3 conv, or fewer head channels), a cap on the peaks sent to NMS (e.g. the "
        "top 50 instead of `top_k` = 500), and keeping the text cache warm for the prompt "
        "history."
    ),
    "`encode_scene` + `ground` median": (
        "**`encode_scene` + `ground`.** The scene half adds the pillar encoders, both "
        "backbones and BACA at three stages to `ground` (stage table); BACA's time at 80 x 80 "
        "is its softmax attentions between 6400 queries and 144 agents and its four linear "
        "projections per direction (cProfile). Fix: fusing the Q/K/V projections of each "
        "direction into one linear layer."
    ),
    "bi_mhca / BACA 12x12 latency": (
        "**Fusion latency ratio.** bi_mhca's time is its `L x L` attention; the ratio to BACA "
        "shrinks where BACA's projections dominate (small maps)."
    ),
    "bi_mhca / BACA 12x12 peak memory": (
        "**Fusion memory ratio.** The model's bi_mhca splits its queries into chunks "
        "(`FusionConfig.mhca_chunk`), which bounds its memory by design: its peak is a chunk's "
        "raw and scaled `heads x chunk x L` scores, while BACA's is its `(heads, L, agents)` "
        "attention maps. The paper's Bi-MHCA is unchunked: the fusion section's 'unchunked' "
        "column and finding give that ratio (at 160 x 160 the two `4 x 25600 x 25600` float32 "
        "score tensors alone are 19.5 GiB, more than this machine can hold), which is the "
        "quadratic cost the FLOP ratio shows. Fix, if the measured ratio matters more than "
        "bounded memory: a larger `mhca_chunk`."
    ),
    "`encode_scene` time / FLOP floor": (
        "**`encode_scene` against its FLOP floor.** The floor section's stage tables say where "
        "the time above the floor goes. The network's FLOP stages by themselves (the backbones "
        "and fusion rows, and the neck and head timed from outside) add up to more than twice "
        "the whole call's floor with two threads: the small preset's convolutions and "
        "attention products on 20 x 20 to 80 x 80 maps run at a half or less of the "
        "1024 x 1024 matmul's rate (the backbones, the best of them, at 1.6-1.7x their "
        "floor; the one-thread section shows what a second thread buys them), and BACA's "
        "softmaxes, about 5 M exponentials a scene, count no FLOPs. So the 2x target is out of "
        "reach on this machine even with the FLOP-free work (pillars, decoding, candidate "
        "description, since issue 20's compiled passes about a fifth of the call) at zero. "
        "With one thread, the app's default (`launch.py --threads 1`), the floor_1thread "
        "section measures the same code at or near 2x. What would close the rest: larger "
        "maps per operation (the `paper` preset), a CPU kernel that fuses BACA's score "
        "products with their softmax, or a GPU."
    ),
    "`ground` (new prompt) time / FLOP floor": (
        "**`ground` against its FLOP floor.** MiniLM for one prompt is 15-30 matrix rows "
        "against 42 MB of weights, more than this machine's shared L3, read once per prompt "
        "(through oneDNN's inner product on prepacked weights, the fastest form here for so "
        "few rows), about 3x its floor; the referent stage is many small operations on 40 "
        "candidates (three transformer blocks of width 128) whose overhead exceeds their "
        "0.06 GFLOP (about 10x its floor with either thread count); the answer (ranking, "
        "heatmap; the heatmap's windows are kept per scene) has none. With one thread the "
        "floor doubles and the same code meets 4x: the floor_1thread section."
    ),
    "`model.evaluate` prompts/s": (
        "**Evaluation throughput.** The evaluation section times the whole command; with the "
        "cores shared, each run's start-up, reading and metrics are as slow as the load makes "
        "them. This checkout predicts with `--workers` processes (default: the usable cores, "
        "here this process and one spawned worker, one torch thread each; "
        "`model/evaluation/predict_pool.py`), which uses cores that other jobs leave free and "
        "nothing more: while a training holds the cores, one process or two get about the same "
        "share of CPU (`python -m model.evaluate --data /tmp/h5-eval --split all --workers 2` "
        "under `/usr/bin/time` with `OMP_NUM_THREADS=1`, at load 4.5: 35.5 s wall and 32.6 "
        "CPU-s; with `--workers 1`, 33.4 s and 30.5 CPU-s), so under load the ratio is that of CPU work "
        "per prompt; the workers' gain shows only when the cores are free."
    ),
    "KNN / DGGF": (
        "**Graph cost.** The model's default form of DGGF's graph (`dynamic_max_relative`, "
        "a grouped pairwise maximum, chosen for the speed of the training step) is slower "
        "without gradients than the roll loop of the same graph (`dynamic_max_relative_loop`, "
        "same values): the graph section's finding gives both ratios to KNN. The model "
        "already switches to the roll loop when no gradient is recorded "
        "(`model/nets/dggf.py`), so `ground` runs the faster form."
    ),
    "held-out detection recall gap": (
        "**Held-out sensors.** The sensor-shift section's table says which rig: the HDL-64 "
        "mounted 0.3 m lower and pitched 2 degrees down. The detector learned heights above a "
        "level ground 1.70 m below the sensor; a pitched sensor's ground rises ahead of it "
        "(0.7 m at 20 m), and boxes are placed and scored in its own frame. Measured fixes and "
        "what is left: docs/RESULTS.md, 'Held-out sensors (issue 38)'."
    ),
}
"""Explanations added under the target summary for each missed target (by name prefix)."""


def _run(cmd: Sequence[str]) -> tuple[int, float]:
    print(f"\n$ {shlex.join(cmd)}", flush=True)
    t0 = time.perf_counter()
    code = subprocess.call(list(cmd), cwd=REPO)
    return code, time.perf_counter() - t0


def run_benchmarks(names: Sequence[str], quick: bool, threads: int | None = None) -> dict[str, str]:
    """Run the named benchmarks (and ``synth``) one process each; returns failures by name.

    ``threads`` is passed on as ``--threads`` (None: each benchmark's default)."""
    failures = {}
    for name in names:
        if name == SYNTH:
            if not SYNTH_SCRIPT.is_file():
                failures[name] = f"{SYNTH_SCRIPT.relative_to(REPO)} does not exist"
                continue
            cmd = [sys.executable, str(SYNTH_SCRIPT.relative_to(REPO)), *SYNTH_ARGS[quick]]
        else:
            cmd = [sys.executable, "-m", MODULES[name]]
            cmd += ["--quick"] if quick else []
            cmd += ["--threads", str(threads)] if threads is not None else []
        code, seconds = _run(cmd)
        print(f"[{name}: exit {code} after {seconds:.0f} s]", flush=True)
        if code != 0:
            failures[name] = f"exit code {code} after {seconds:.0f} s (see the console output)"
    return failures


# --------------------------------------------------------------------------- the document


def _rel(path: Path) -> str:
    try:
        return str(path.relative_to(REPO))
    except ValueError:
        return str(path)


def _synth_section(path: Path, failure: str | None) -> str:
    """The scene generation section from ``bench_synth.py``'s own JSON (its own format)."""
    lines = ["## Scene generation speed", ""]
    if failure is not None and not path.is_file():
        return "\n".join([*lines, f"*Not measured:* {failure}.", ""])
    if not path.is_file():
        return "\n".join(
            [
                *lines,
                f"*Not measured:* `{_rel(path)}` is missing (HOOK: run "
                "`python bench/perf/bench_synth.py`).",
                "",
            ]
        )
    try:
        data = json.loads(read_text_file(path, "results file", ValueError))
        command, table = data["command"], data["markdown"]
        machine = data.get("machine", {})
    except (ValueError, KeyError, TypeError) as exc:  # JSONDecodeError is a ValueError
        return "\n".join([*lines, f"*Unreadable results* `{_rel(path)}`: {exc}.", ""])
    here = machine_info(command)
    load = machine.get("load_average_before")
    load_text = f"; load average {load:.2f} at the start" if isinstance(load, int | float) else ""
    lines += [
        f"*Machine:* {here.hardware()}; Python {here.python}, {here.platform}{load_text}; "
        f"{here.date}.  ",
        f"*Command:* `{command}` (script by the scenes/ owner; its JSON is `{_rel(path)}`).",
    ]
    if failure is not None:
        lines.append(f"*This run failed ({failure}); the table is from the previous run.*")
    lines += ["", table, ""]
    return "\n".join(lines)


def _targets(results: dict[str, BenchResult]) -> list[tuple[str, Target]]:
    out = []
    for name, result in results.items():
        for t in result.data.get("targets", []):
            try:
                out.append((name, Target(**t)))
            except TypeError as exc:
                raise BenchResultError(f"{name}: bad target entry {t!r}: {exc}") from exc
    return out


def render(
    results: dict[str, BenchResult],
    failures: dict[str, str],
    synth_path: Path,
    command: str,
    seconds: float | None,
) -> str:
    """The whole ``docs/PERFORMANCE.md``."""
    targets = _targets(results)
    rows = []
    for name, t in targets:
        sign = ">=" if t.higher_is_better else "<="
        rows.append(
            (
                t.name,
                f"{t.value:,.1f} {t.unit}",
                f"{sign} {t.limit:g} {t.unit}",
                "met" if t.met else "**MISSED**",
                f"[{name}](#{_anchor(results[name].title)})",
            )
        )
    summary = Table(
        title="",
        columns=("target", "measured", "target", "verdict", "section"),
        rows=tuple(rows),
        align=("l", "r", "r", "l", "l"),
    )
    if seconds is not None:
        made = f"Generated by `{command}` in {seconds / 60:.1f} min."
    else:
        made = f"Rebuilt by `{command}` from the stored results."
    parts = [
        "# Performance",
        "",
        "<!-- Generated by `python -m bench.run_all` (`make bench`) from bench/results/*.json; "
        "do not edit by hand. -->",
        "",
        f"{made} Every section below says on which machine and with "
        "which command its tables were made; repeat one with that command (it rewrites its "
        "`bench/results/<name>.json`), then `python -m bench.run_all --no-run` rebuilds this "
        "page. Timings are wall-clock medians; on a machine whose cores are shared with other "
        "jobs (see each section's load average) they are noisy and pessimistic.",
        "",
        "## Targets",
        "",
        summary.to_markdown() if rows else "*No results yet.*",
    ]
    missed = [
        note
        for _, t in targets
        if not t.met
        for prefix, note in MISS_NOTES.items()
        if t.name.startswith(prefix)
    ]
    if missed:
        parts += ["", "### Notes on the misses", ""]
        parts += [f"- {note}" for note in dict.fromkeys(missed)]
    if failures:
        parts += ["", "### Failed in this run", ""]
        parts += [f"- `{name}`: {why}" for name, why in failures.items()]
    parts.append("")
    for name in (*BENCHMARKS, *MANUAL):
        if name in results:
            section = results[name].to_markdown()
            if name in failures:
                section = section.replace(
                    "\n", f"\n\n*This run failed ({failures[name]}); below: the previous run.*\n", 1
                )
            parts.append(section)
        elif name in failures:
            parts += [f"## {name}", "", f"*Not measured:* {failures[name]}.", ""]
    parts.append(_synth_section(synth_path, failures.get(SYNTH)))
    return "\n".join(parts).rstrip() + "\n"


def _anchor(title: str) -> str:
    """GitHub's heading anchor of ``title``."""
    kept = "".join(ch for ch in title.lower() if ch.isalnum() or ch in " -_")
    return kept.replace(" ", "-")


def load_results(directory: Path = RESULTS_DIR) -> dict[str, BenchResult]:
    """The results of :data:`BENCHMARKS` and :data:`MANUAL` present in ``directory``."""
    out = {}
    for name in (*BENCHMARKS, *MANUAL):
        path = directory / f"{name}.json"
        if path.is_file():
            out[name] = read_result(path)
    return out


@dataclass(frozen=True, kw_only=True)
class RunAllOptions:
    """The flags of ``python -m bench.run_all``."""

    quick: bool = option(False, help="smoke run (fewer repetitions)")
    only: tuple[str, ...] | None = option(
        None,
        nargs="+",
        choices=(*BENCHMARKS, SYNTH),
        help="run only these; the document keeps the others' previous results",
    )
    threads: int | None = option(
        None, help="torch threads of every benchmark (default: theirs: 1, floor 2)"
    )
    no_run: bool = option(False, help="only rebuild docs/PERFORMANCE.md from the results")
    doc: Path = option(PERFORMANCE_DOC, help="document to write")


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.run_all``'s parser."""
    return command_parser("python -m bench.run_all", __doc__.splitlines()[0], RunAllOptions)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = from_args(RunAllOptions, build_parser().parse_args(argv))
    start = time.perf_counter()
    failures: dict[str, str] = {}
    if not args.no_run:
        failures = run_benchmarks(args.only or [*BENCHMARKS, SYNTH], args.quick, args.threads)
    seconds = None if args.no_run else time.perf_counter() - start
    results = load_results()
    command = shlex.join(["python", "-m", "bench.run_all", *argv])
    text = render(results, failures, RESULTS_DIR / f"{SYNTH}.json", command, seconds)
    args.doc.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.doc, text)
    print(f"\nwrote {args.doc} ({len(results)} benchmark results", end="")
    print(f", {seconds / 60:.1f} min)" if seconds is not None else ")")
    if failures:
        print("failed: " + ", ".join(f"{k} ({v})" for k, v in failures.items()), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
