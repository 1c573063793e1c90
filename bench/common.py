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
from dataclasses import asdict, dataclass
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
from scenes.utils.cli import command_parser, from_args, option

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
    "BenchOptions",
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
    "bench_parser",
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
    """The command that reproduces this run, e.g. ``python -m bench.perf.latency --quick``."""
    return shlex.join(["python", "-m", module, *argv])


@dataclass(frozen=True, kw_only=True)
class BenchOptions:
    """The flags every benchmark shares (:func:`bench_main`).

    Attributes:
        quick: Fewer repetitions and sizes (a smoke run).
        threads: torch's intra-op CPU threads (None: the benchmark's default, ``default_threads``
            of :func:`bench_main`).
        out_dir: Where the JSON goes.
    """

    quick: bool = option(False, help="fewer repetitions and sizes (a smoke run)")
    threads: int | None = option(
        None,
        help=f"torch intra-op CPU threads (default: the benchmark's, {DEFAULT_THREADS} as the "
        "app's launch.py unless its docstring says otherwise)",
    )
    out_dir: Path = option(RESULTS_DIR, help="where the JSON goes")


def bench_parser(
    module: str, description: str = "", options: type | None = None
) -> argparse.ArgumentParser:
    """The parser of ``python -m <module>``: :class:`BenchOptions`' flags, then those of the
    benchmark's own ``options`` dataclass (its fields are ``run``'s keyword arguments)."""
    own = () if options is None else (options,)
    return command_parser(f"python -m {module}", description, BenchOptions, *own)


def bench_main(
    module: str,
    run: Callable[..., BenchResult],
    argv: Sequence[str] | None = None,
    description: str = "",
    default_threads: int = DEFAULT_THREADS,
    options: type | None = None,
) -> int:
    """Command line shared by the benchmarks: ``[--quick] [--threads N] [--out-dir DIR]``.

    Sets torch's intra-op threads (default ``default_threads``), runs ``run(quick=...,
    command=..., **own)``, prints the Markdown and writes the JSON; ``options``: the benchmark's
    own flags, a frozen dataclass whose fields are passed to ``run`` by name.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = bench_parser(module, description, options)
    args = parser.parse_args(argv)
    shared = from_args(BenchOptions, args)
    threads = default_threads if shared.threads is None else shared.threads
    if threads < 1:
        parser.error(f"--threads must be >= 1, got {threads}")
    torch.set_num_threads(threads)
    own = {} if options is None else asdict(from_args(options, args))
    result = run(quick=shared.quick, command=command_line(module, argv), **own)
    print(result.to_markdown())
    path = write_result(result, shared.out_dir)
    print(f"wrote {path}")
    return 0
