"""Shared helpers of the benchmarks, in one namespace, and their command line.

The helpers live in three modules (issue 12: measurement, report rendering and workloads apart),
all re-exported here so that ``from bench.common import ...`` keeps working:

- :mod:`bench.report`: every benchmark returns a :class:`BenchResult` (a title, the
  :class:`Machine` it ran on with the exact command, Markdown :class:`Table` s, :class:`Target` s,
  findings and the raw numbers) that is written to ``bench/results/<name>.json``
  (:func:`write_result`) and rendered into ``docs/PERFORMANCE.md`` by :mod:`bench.run_all`
  (:func:`read_result`, :meth:`BenchResult.to_markdown`); the number formats (``fmt_*``).
- :mod:`bench.measure`: wall-clock timing (:func:`time_ms`, :func:`interleaved_ms`,
  :func:`summarize`), FLOPs (:func:`count_flops`), parameters and peak memory
  (:func:`peak_memory_bytes`, :class:`LiveTensorMemory`).
- :mod:`bench.workloads`: :func:`synthetic_scenes` draws scenes and prompts from the synthetic
  generator; :func:`warm_up` runs a model once before it is timed.

This module adds the command line every benchmark shares (:func:`bench_main`).
"""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import torch

from bench.measure import (
    FlopCount,
    LiveTensorMemory,
    Stats,
    count_flops,
    count_params,
    interleaved_ms,
    peak_memory_bytes,
    percentile,
    summarize,
    synchronize,
    time_ms,
)
from bench.report import (
    PERFORMANCE_DOC,
    REPO,
    RESULTS_DIR,
    SCHEMA,
    BenchResult,
    BenchResultError,
    Machine,
    Table,
    Target,
    fmt_bytes,
    fmt_count,
    fmt_flops,
    fmt_ms,
    fmt_ratio,
    machine_info,
    read_result,
    result_from_json,
    write_result,
)
from bench.workloads import WARM_UP_PROMPTS, SceneWorkload, synthetic_scenes, warm_up

DEFAULT_THREADS = 1
"""Torch intra-op threads of the benchmarks unless ``--threads`` says otherwise: the app's default
(``launch.py --threads 1``). On a 2-core machine shared with other jobs, torch's OpenMP threads
wait on each other at every operation and two threads can be many times slower than one; the
latency benchmark measures both."""

__all__ = [
    "DEFAULT_THREADS",
    "PERFORMANCE_DOC",
    "REPO",
    "RESULTS_DIR",
    "SCHEMA",
    "WARM_UP_PROMPTS",
    "BenchResult",
    "BenchResultError",
    "FlopCount",
    "LiveTensorMemory",
    "Machine",
    "SceneWorkload",
    "Stats",
    "Table",
    "Target",
    "bench_main",
    "command_line",
    "count_flops",
    "count_params",
    "fmt_bytes",
    "fmt_count",
    "fmt_flops",
    "fmt_ms",
    "fmt_ratio",
    "interleaved_ms",
    "machine_info",
    "peak_memory_bytes",
    "percentile",
    "read_result",
    "result_from_json",
    "summarize",
    "synchronize",
    "synthetic_scenes",
    "time_ms",
    "warm_up",
    "write_result",
]


# --------------------------------------------------------------------------- command line


def command_line(module: str, argv: Sequence[str]) -> str:
    """The command that reproduces this run, e.g. ``python -m bench.latency --quick``."""
    return shlex.join(["python", "-m", module, *argv])


def bench_main(
    module: str,
    run: Callable[..., BenchResult],
    argv: Sequence[str] | None = None,
    description: str = "",
    default_threads: int = DEFAULT_THREADS,
    options: Callable[[argparse.ArgumentParser], None] | None = None,
) -> int:
    """Command line shared by the benchmarks: ``[--quick] [--threads N] [--out-dir DIR]``.

    Sets torch's intra-op threads (default ``default_threads``), runs ``run(quick=...,
    command=..., **own)``, prints the Markdown and writes the JSON; ``options`` adds a
    benchmark's own arguments to the parser, passed to ``run`` by their ``dest`` names.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog=f"python -m {module}", description=description)
    parser.add_argument(
        "--quick", action="store_true", help="fewer repetitions and sizes (a smoke run)"
    )
    parser.add_argument(
        "--threads",
        type=int,
        default=default_threads,
        help=f"torch intra-op CPU threads (default {default_threads}"
        + (", as the app's launch.py)" if default_threads == DEFAULT_THREADS else ")"),
    )
    parser.add_argument("--out-dir", type=Path, default=RESULTS_DIR, help="where the JSON goes")
    if options is not None:
        options(parser)
    args = parser.parse_args(argv)
    if args.threads < 1:
        parser.error(f"--threads must be >= 1, got {args.threads}")
    torch.set_num_threads(args.threads)
    own = {k: v for k, v in vars(args).items() if k not in ("quick", "threads", "out_dir")}
    result = run(quick=args.quick, command=command_line(module, argv), **own)
    print(result.to_markdown())
    path = write_result(result, args.out_dir)
    print(f"wrote {path}")
    return 0
