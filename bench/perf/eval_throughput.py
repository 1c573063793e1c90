"""Throughput of ``python -m model.evaluate`` on a 300-prompt root: ``python -m bench.eval_throughput``.

What a researcher runs to evaluate a whole split, timed from outside as one command (process
start, imports, checkpoint and MiniLM loading, reading every sample, encoding, grounding, the
class-noun baseline, the official metric with its per-type and per-depth tables, writing the
prediction files and the JSON): wall-clock seconds of the process and prompts per second.

Workload: ``python -m scenes.synth --frames 300 --prompts-per-world 1 --seed 5 --no-camera``
(300 samples, one prompt per world: every sample is a scene to encode), written once into
``--root`` (default ``/tmp/talk2pc-eval-300``) with an ``all`` split listing every sample; the
command timed is ``python -m model.evaluate --data ROOT --split all --out ... --json ...`` with the
bundled checkpoint, its default ``--workers`` (since issue 20: the usable cores, each predicting
process with one torch thread) and torch's default threads (``--eval-threads N``:
``OMP_NUM_THREADS=N``, which the code before issue 20 uses inside its one process).

``--baseline-code DIR``: also time the same command run from another checkout (the code before
issue 20's changes: ``git archive <commit> | tar -x -C DIR``), alternating the two run by run so
that both see the same load; the table sets them side by side. ``--repeats`` runs of each.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from bench.common import bench_main, bench_parser
from bench.measure import summarize
from bench.report import REPO, BenchResult, Table, Target, fmt_ratio, machine_info
from scenes.talk2radar.root import Talk2RadarRoot, Talk2RadarWriter
from scenes.utils.cli import option

PROMPTS = 300
SEED = 5
SPLIT = "all"
TARGET_SPEEDUP = 2.0
"""Issue 20: at least twice the prompts per second of the code before it."""


def ensure_root(root: Path, prompts: int = PROMPTS, seed: int = SEED) -> list[str]:
    """Generate the root once (resumable: ``scenes.synth`` completes what is there) and list
    every sample in the ``all`` split; returns the ids."""
    synth = [sys.executable, "-m", "scenes.synth", "--out", str(root), "--frames", str(prompts)]
    synth += ["--prompts-per-world", "1", "--seed", str(seed), "--no-camera", "--quiet"]
    subprocess.run(synth, cwd=REPO, check=True)
    reader = Talk2RadarRoot(root)
    ids = sorted({i for split in ("train", "val", "test") for i in reader.ids(split)})
    Talk2RadarWriter(root, radar_folder=reader.radar_folder or "radar_5frames").write_image_sets(
        {SPLIT: ids}
    )
    return ids


def time_evaluate(code: Path, root: Path, threads: int | None = None) -> float:
    """Wall-clock seconds of ``python -m model.evaluate`` on ``root`` run from checkout ``code``
    (``threads``: its torch threads, through ``OMP_NUM_THREADS``; None: torch's default)."""
    env = dict(os.environ)
    if threads is not None:
        env["OMP_NUM_THREADS"] = str(threads)
    with tempfile.TemporaryDirectory(prefix="eval-throughput-") as tmp:
        cmd = [sys.executable, "-m", "model.evaluate", "--data", str(root), "--split", SPLIT]
        cmd += ["--out", str(Path(tmp) / "preds"), "--json", str(Path(tmp) / "eval.json")]
        t0 = time.perf_counter()
        subprocess.run(
            cmd, cwd=code, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
        )
        return time.perf_counter() - t0


def run(
    quick: bool = False,
    command: str = "python -m bench.eval_throughput",
    root: Path = Path("/tmp/talk2pc-eval-300"),
    repeats: int | None = None,
    baseline_code: Path | None = None,
    eval_threads: int | None = None,
) -> BenchResult:
    """Time the evaluation (see the module docstring)."""
    start = time.perf_counter()
    machine = machine_info(command)
    ids = ensure_root(root)
    n = repeats or (1 if quick else 3)
    codes = {"now": REPO} if baseline_code is None else {"baseline": baseline_code, "now": REPO}
    seconds: dict[str, list[float]] = {k: [] for k in codes}
    for r in range(n):
        for name in codes if r % 2 == 0 else list(codes)[::-1]:
            seconds[name].append(time_evaluate(codes[name], root, eval_threads))
    rows = []
    rate = {}
    for name, values in seconds.items():
        s = summarize(values)
        rate[name] = len(ids) / s.median
        label = "code before issue 20" if name == "baseline" else "this checkout"
        rows.append(
            (
                label,
                str(s.n),
                f"{s.median:.1f}",
                f"{s.min:.1f}",
                f"{s.max:.1f}",
                f"{rate[name]:.2f}",
            )
        )
    targets, findings = [], []
    if "baseline" in rate:
        speedup = rate["now"] / rate["baseline"]
        targets.append(
            Target(
                "`model.evaluate` prompts/s against the code before issue 20 (300 prompts)",
                speedup,
                TARGET_SPEEDUP,
                "x",
                True,
            )
        )
        findings.append(targets[0].describe())
        rows.append(("**speed-up**", "", "", "", "", f"**{fmt_ratio(speedup)}**"))
    findings.append(
        f"Root: {len(ids)} samples, one prompt per world (`python -m scenes.synth --out {root} "
        f"--frames {PROMPTS} --prompts-per-world 1 --seed {SEED} --no-camera`), split `{SPLIT}` "
        "listing all of them; runs alternate between the checkouts; the cores are shared with "
        "other jobs (load average above)."
    )
    threads = "torch's default threads" if eval_threads is None else f"{eval_threads} thread(s)"
    table = Table(
        f"`python -m model.evaluate --data ROOT --split all` (whole process, {threads})",
        ("code", "runs", "median s", "min s", "max s", "prompts/s (median)"),
        tuple(rows),
        ("Wall clock of the whole command: start-up, loading, every sample, metrics, files.",),
    )
    suffix = "" if eval_threads is None else f"_{eval_threads}thread"
    return BenchResult(
        name=f"eval_throughput{suffix}",
        title=f"Evaluation throughput (`model.evaluate`, 300 prompts, {threads})",
        machine=machine,
        tables=(table,),
        findings=tuple(findings),
        data={
            "samples": len(ids),
            "seconds": seconds,
            "prompts_per_second": rate,
            "baseline_code": None if baseline_code is None else str(baseline_code),
            "targets": [vars(t) for t in targets],
        },
        seconds=time.perf_counter() - start,
    )


@dataclass(frozen=True, kw_only=True)
class EvalThroughputOptions:
    """This benchmark's own flags (see the module docstring; :func:`run`'s keyword arguments)."""

    root: Path = option(Path("/tmp/talk2pc-eval-300"))
    repeats: int | None = option(None, help="runs of each (default 3)")
    baseline_code: Path | None = option(None, help="an older checkout")
    eval_threads: int | None = option(
        None, help="torch threads of the timed commands (OMP_NUM_THREADS; default: torch's own)"
    )


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.eval_throughput``'s parser."""
    return bench_parser("bench.eval_throughput", __doc__.splitlines()[0], EvalThroughputOptions)


def main(argv: list[str] | None = None) -> int:
    return bench_main(
        "bench.eval_throughput", run, argv, __doc__.splitlines()[0], options=EvalThroughputOptions
    )


if __name__ == "__main__":
    raise SystemExit(main())
