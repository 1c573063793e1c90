"""Shared output and measurement helpers of the benchmarks.

Output: every benchmark returns a :class:`BenchResult` (a title, the :class:`Machine` it ran on with
the exact command, Markdown :class:`Table` s, findings and the raw numbers) that is written to
``bench/results/<name>.json`` (:func:`write_result`) and rendered into ``docs/PERFORMANCE.md`` by
:mod:`bench.run_all` (:func:`read_result`, :meth:`BenchResult.to_markdown`).

Measurements:

- Wall-clock times in milliseconds (:func:`time_ms`), CUDA synchronised before every reading;
  summarised by :func:`summarize` (median, p90 with linear interpolation between order statistics,
  mean, min, max).
- FLOPs with :class:`torch.utils.flop_counter.FlopCounterMode` (:func:`count_flops`): it counts
  matrix products and convolutions only (2 FLOPs per multiply-add; element-wise ops, softmax and
  pooling are not counted), per module and in total.
- Peak memory (:func:`peak_memory_bytes`): the peak, during one call, of the bytes of tensors
  allocated *by that call* and still alive (inputs and parameters are not counted; outputs are).
  On CUDA ``torch.cuda.max_memory_allocated`` minus the allocation before the call; on the CPU the
  same quantity tracked per tensor storage by :class:`LiveTensorMemory` (a ``TorchDispatchMode``;
  ``tracemalloc`` does not see torch's allocations and the process RSS does not shrink when glibc
  keeps freed pages). Scratch buffers private to a CPU kernel are not seen.

Workload: :func:`synthetic_scenes` draws scenes and prompts from the synthetic generator
(:func:`scenes.synth.synthesize`), so that point counts and prompts are the app's.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import os
import platform
import shlex
import sys
import time
import weakref
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_flatten
from torch.utils.flop_counter import FlopCounterMode

REPO = Path(__file__).resolve().parents[1]
RESULTS_DIR = REPO / "bench" / "results"
PERFORMANCE_DOC = REPO / "docs" / "PERFORMANCE.md"
SCHEMA = "talk2pc-bench/1"
DEFAULT_THREADS = 1
"""Torch intra-op threads of the benchmarks unless ``--threads`` says otherwise: the app's default
(``launch.py --threads 1``). On a 2-core machine shared with other jobs, torch's OpenMP threads
wait on each other at every operation and two threads can be many times slower than one; the
latency benchmark measures both."""


class BenchResultError(ValueError):
    """A results file that cannot be read back (names the file and the field)."""


# --------------------------------------------------------------------------- machine


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def _memory_gib() -> float:
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemTotal:"):
                    return int(line.split()[1]) / 1024**2
    except (OSError, ValueError, IndexError):
        pass
    return float("nan")


@dataclass(frozen=True)
class Machine:
    """Where and how a benchmark ran.

    Attributes:
        cpu_model: ``model name`` of ``/proc/cpuinfo``.
        cores: Logical CPUs usable by the process.
        memory_gib: Total RAM.
        torch_version: ``torch.__version__``.
        torch_threads: ``torch.get_num_threads()`` (intra-op threads).
        python: Python version.
        platform: ``platform.platform()``.
        gpu: CUDA device name, or None.
        load_average: 1, 5 and 15 minute load averages at the start (other processes sharing
            the cores make timings noisy).
        date: Start time, ISO 8601, UTC.
        command: The command line that produced the result.
    """

    cpu_model: str
    cores: int
    memory_gib: float
    torch_version: str
    torch_threads: int
    python: str
    platform: str
    gpu: str | None
    load_average: tuple[float, float, float]
    date: str
    command: str

    def describe(self) -> str:
        """One Markdown line describing the machine (without the command)."""
        gpu = f"GPU {self.gpu}" if self.gpu else "no GPU"
        load = " / ".join(f"{v:.2f}" for v in self.load_average)
        threads = f"{self.torch_threads} thread{'' if self.torch_threads == 1 else 's'}"
        return (
            f"{self.hardware()}, {gpu}; torch {self.torch_version} ({threads}), "
            f"Python {self.python}, {self.platform}; load average {load} (1/5/15 min) at the "
            f"start; {self.date}"
        )

    def hardware(self) -> str:
        """CPU model, cores and RAM, e.g. ``"AMD EPYC, 2 cores, 23.5 GiB RAM"``."""
        return f"{self.cpu_model}, {self.cores} cores, {self.memory_gib:.1f} GiB RAM"


def machine_info(command: str) -> Machine:
    """Describe this machine now; ``command`` is the command line being run."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count() or 1
    gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else None
    load = tuple(float(v) for v in os.getloadavg()) if hasattr(os, "getloadavg") else (0.0,) * 3
    return Machine(
        cpu_model=_cpu_model(),
        cores=cores,
        memory_gib=_memory_gib(),
        torch_version=torch.__version__,
        torch_threads=torch.get_num_threads(),
        python=platform.python_version(),
        platform=platform.platform(),
        gpu=gpu,
        load_average=(load[0], load[1], load[2]),
        date=dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        command=command,
    )


# --------------------------------------------------------------------------- tables and results


def _cell(value: object) -> str:
    return str(value).replace("|", "\\|").replace("\n", " ")


@dataclass(frozen=True)
class Table:
    """A Markdown table.

    Attributes:
        title: Shown as a level-3 heading above the table (omitted when empty).
        columns: Column headers.
        rows: Cells as already formatted strings, one tuple per row, ``len(columns)`` each.
        notes: Lines shown under the table as a bullet list.
        align: ``"l"`` or ``"r"`` per column; default: first column left, the others right.
    """

    title: str
    columns: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    notes: tuple[str, ...] = ()
    align: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for i, row in enumerate(self.rows):
            if len(row) != len(self.columns):
                raise ValueError(
                    f"table {self.title!r}: row {i} has {len(row)} cells for "
                    f"{len(self.columns)} columns"
                )
        if self.align and (len(self.align) != len(self.columns) or set(self.align) - {"l", "r"}):
            raise ValueError(
                f"table {self.title!r}: align must be 'l'/'r' per column, got {self.align!r}"
            )

    def to_markdown(self) -> str:
        """The table (with its title and notes) as Markdown."""
        align = self.align or ("l",) + ("r",) * (len(self.columns) - 1)
        rule = ["---" if a == "l" else "---:" for a in align]
        lines = [f"### {self.title}", ""] if self.title else []
        lines.append("| " + " | ".join(_cell(c) for c in self.columns) + " |")
        lines.append("| " + " | ".join(rule) + " |")
        lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in self.rows]
        if self.notes:
            lines.append("")
            lines += [f"- {note}" for note in self.notes]
        return "\n".join(lines)


@dataclass(frozen=True)
class BenchResult:
    """The outcome of one benchmark.

    Attributes:
        name: File stem of the results (``bench/results/<name>.json``), e.g. ``"latency"``.
        title: Section heading in ``docs/PERFORMANCE.md``.
        machine: Where and with which command it ran.
        tables: The tables, in order.
        findings: Targets met or missed, profiles of the misses, caveats (Markdown lines).
        data: The raw numbers (JSON-serialisable).
        seconds: Wall time of the whole benchmark.
    """

    name: str
    title: str
    machine: Machine
    tables: tuple[Table, ...]
    findings: tuple[str, ...] = ()
    data: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0

    def to_markdown(self, level: int = 2) -> str:
        """The section: heading, machine and command, tables, findings."""
        parts = [
            f"{'#' * level} {self.title}",
            "",
            f"*Machine:* {self.machine.describe()}.  ",
            f"*Command:* `{self.machine.command}` (ran {self.seconds:.0f} s).",
        ]
        for table in self.tables:
            parts += ["", table.to_markdown()]
        if self.findings:
            parts += ["", "**Findings**", ""]
            parts += [f"- {line}" for line in self.findings]
        return "\n".join(parts) + "\n"

    def to_json(self) -> dict[str, Any]:
        """A JSON-serialisable dict (inverse: :func:`result_from_json`)."""
        return {
            "schema": SCHEMA,
            "name": self.name,
            "title": self.title,
            "machine": asdict(self.machine),
            "seconds": self.seconds,
            "tables": [asdict(t) for t in self.tables],
            "findings": list(self.findings),
            "data": self.data,
        }


def _need(data: dict, key: str, kind: type | tuple[type, ...], where: str) -> Any:
    if not isinstance(data, dict) or key not in data:
        raise BenchResultError(f"{where}: missing field {key!r}")
    value = data[key]
    if not isinstance(value, kind):
        raise BenchResultError(f"{where}: field {key!r} has type {type(value).__name__}")
    return value


def result_from_json(data: dict[str, Any], where: str = "result") -> BenchResult:
    """Rebuild a :class:`BenchResult`; :class:`BenchResultError` names ``where`` and the field."""
    if _need(data, "schema", str, where) != SCHEMA:
        raise BenchResultError(f"{where}: field 'schema' is {data['schema']!r}, not {SCHEMA!r}")
    m = _need(data, "machine", dict, where)
    mw = f"{where}: machine"
    machine = Machine(
        cpu_model=_need(m, "cpu_model", str, mw),
        cores=_need(m, "cores", int, mw),
        memory_gib=float(_need(m, "memory_gib", (int, float), mw)),
        torch_version=_need(m, "torch_version", str, mw),
        torch_threads=_need(m, "torch_threads", int, mw),
        python=_need(m, "python", str, mw),
        platform=_need(m, "platform", str, mw),
        gpu=m.get("gpu"),
        load_average=tuple(float(v) for v in _need(m, "load_average", list, mw)),  # type: ignore[arg-type]
        date=_need(m, "date", str, mw),
        command=_need(m, "command", str, mw),
    )
    tables = []
    for i, t in enumerate(_need(data, "tables", list, where)):
        tw = f"{where}: tables[{i}]"
        try:
            tables.append(
                Table(
                    title=_need(t, "title", str, tw),
                    columns=tuple(_need(t, "columns", list, tw)),
                    rows=tuple(tuple(r) for r in _need(t, "rows", list, tw)),
                    notes=tuple(t.get("notes", ())),
                    align=tuple(t.get("align", ())),
                )
            )
        except ValueError as exc:
            if isinstance(exc, BenchResultError):
                raise
            raise BenchResultError(f"{tw}: {exc}") from exc
    return BenchResult(
        name=_need(data, "name", str, where),
        title=_need(data, "title", str, where),
        machine=machine,
        tables=tuple(tables),
        findings=tuple(_need(data, "findings", list, where)),
        data=_need(data, "data", dict, where),
        seconds=float(_need(data, "seconds", (int, float), where)),
    )


def write_result(result: BenchResult, directory: Path = RESULTS_DIR) -> Path:
    """Write ``<directory>/<name>.json`` (atomically) and return its path."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{result.name}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(result.to_json(), indent=1, allow_nan=True) + "\n")
    os.replace(tmp, path)
    return path


def read_result(path: Path) -> BenchResult:
    """Read a file written by :func:`write_result`."""
    try:
        data = json.loads(Path(path).read_text())
    except json.JSONDecodeError as exc:
        raise BenchResultError(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})") from exc
    return result_from_json(data, str(path))


# --------------------------------------------------------------------------- statistics and timing


def percentile(values: Sequence[float], q: float) -> float:
    """The ``q``-th percentile (0..100), linear interpolation between order statistics."""
    if not values:
        raise ValueError("percentile of no values")
    if not 0.0 <= q <= 100.0:
        raise ValueError(f"percentile q must be in [0, 100], got {q}")
    ordered = sorted(float(v) for v in values)
    pos = q / 100.0 * (len(ordered) - 1)
    lo, hi = math.floor(pos), math.ceil(pos)
    return ordered[lo] + (ordered[hi] - ordered[lo]) * (pos - lo)


@dataclass(frozen=True)
class Stats:
    """Summary of repeated measurements (same unit as the samples)."""

    n: int
    median: float
    p90: float
    mean: float
    min: float
    max: float


def summarize(samples: Sequence[float]) -> Stats:
    """:class:`Stats` of ``samples`` (at least one)."""
    if not samples:
        raise ValueError("summarize: no samples")
    values = [float(v) for v in samples]
    return Stats(
        n=len(values),
        median=percentile(values, 50.0),
        p90=percentile(values, 90.0),
        mean=sum(values) / len(values),
        min=min(values),
        max=max(values),
    )


def synchronize(device: torch.device | str | None) -> None:
    """Wait for queued CUDA work on ``device`` (no-op on the CPU)."""
    if device is not None and torch.device(device).type == "cuda":
        torch.cuda.synchronize(device)


def time_ms(
    fn: Callable[[], object],
    repeats: int,
    warmup: int = 1,
    device: torch.device | str | None = None,
    max_seconds: float | None = None,
) -> list[float]:
    """Wall-clock milliseconds of ``repeats`` calls of ``fn`` after ``warmup`` untimed calls.

    With ``max_seconds`` the loop stops early once that much time was spent timing (at least one
    call is always timed), so that a slow variant does not blow the time budget.
    """
    if repeats < 1:
        raise ValueError(f"time_ms: repeats must be >= 1, got {repeats}")
    for _ in range(warmup):
        fn()
    synchronize(device)
    samples: list[float] = []
    start = time.perf_counter()
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        synchronize(device)
        samples.append((time.perf_counter() - t0) * 1000.0)
        if max_seconds is not None and time.perf_counter() - start > max_seconds:
            break
    return samples


def interleaved_ms(
    calls: dict[str, Callable[[], object]],
    rounds: int,
    budget_s: float,
    device: torch.device | str | None = None,
) -> dict[str, list[float]]:
    """Milliseconds per call of several variants timed in alternation.

    Round ``r`` calls every variant once, starting from variant ``r mod n``, so that a change of
    the machine's load during the run hits all variants alike and their ratios stay fair. A
    variant stops taking part once ``budget_s`` seconds were spent on it (it is always timed at
    least once). No warm-up is done here.
    """
    if rounds < 1:
        raise ValueError(f"interleaved_ms: rounds must be >= 1, got {rounds}")
    names = list(calls)
    samples: dict[str, list[float]] = {name: [] for name in names}
    spent = dict.fromkeys(names, 0.0)
    for r in range(rounds):
        for i in range(len(names)):
            name = names[(r + i) % len(names)]
            if samples[name] and spent[name] > budget_s:
                continue
            synchronize(device)
            t0 = time.perf_counter()
            calls[name]()
            synchronize(device)
            elapsed = time.perf_counter() - t0
            samples[name].append(elapsed * 1000.0)
            spent[name] += elapsed
    return samples


# --------------------------------------------------------------------------- FLOPs, parameters


@dataclass(frozen=True)
class FlopCount:
    """FLOPs of one call: ``total`` and per module (fully qualified names as FlopCounterMode
    reports them, e.g. ``"TPCNet.lidar.pillars"``; ``"Global"`` is the total)."""

    total: int
    by_module: dict[str, int]


def count_flops(fn: Callable[[], object]) -> FlopCount:
    """FLOPs of ``fn()`` counted by ``FlopCounterMode`` (matmuls and convolutions, 2 per MAC).

    Run it on meta tensors (module ``.to("meta")`` and ``torch.empty(..., device="meta")`` inputs)
    to count a call that would be too slow or too large to execute.
    """
    with FlopCounterMode(display=False) as counter:
        fn()
    by_module = {name: int(sum(ops.values())) for name, ops in counter.get_flop_counts().items()}
    return FlopCount(total=int(counter.get_total_flops()), by_module=by_module)


def count_params(module: torch.nn.Module, trainable_only: bool = False) -> int:
    """Number of parameters of ``module`` (all, or only those with ``requires_grad``)."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad or not trainable_only)


# --------------------------------------------------------------------------- memory


def _storage_key(t: torch.Tensor) -> tuple[int, int] | None:
    if t.layout != torch.strided or t.device.type == "meta":
        return None
    storage = t.untyped_storage()
    nbytes = storage.nbytes()
    if nbytes == 0:
        return None
    return storage.data_ptr(), nbytes


class LiveTensorMemory(TorchDispatchMode):
    """Peak bytes of live tensor storages allocated while the mode is active.

    Every op output whose storage is not one of the op's inputs' storages is a new allocation; it
    counts until the last Python tensor that refers to it (the output or a view of it seen by the
    mode) is freed. Storages that existed before the mode (inputs, parameters) are never counted,
    views of them neither. Use as ``with LiveTensorMemory() as mem: ...; mem.peak``.

    Attributes:
        live: Bytes currently alive.
        peak: Largest ``live`` seen.
    """

    def __init__(self) -> None:
        super().__init__()
        self.live = 0
        self.peak = 0
        self._refs: dict[int, list[int]] = {}  # data_ptr -> [nbytes, referring tensors]

    def _release(self, ptr: int) -> None:
        entry = self._refs.get(ptr)
        if entry is None:
            return
        entry[1] -= 1
        if entry[1] <= 0:
            self.live -= entry[0]
            del self._refs[ptr]

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):  # type: ignore[no-untyped-def]
        kwargs = kwargs or {}
        out = func(*args, **kwargs)
        inputs = {
            key[0]
            for t in tree_flatten((args, kwargs))[0]
            if isinstance(t, torch.Tensor) and (key := _storage_key(t)) is not None
        }
        for t in tree_flatten(out)[0]:
            if not isinstance(t, torch.Tensor):
                continue
            key = _storage_key(t)
            if key is None:
                continue
            ptr, nbytes = key
            if ptr in self._refs:
                self._refs[ptr][1] += 1
            elif ptr not in inputs:
                self._refs[ptr] = [nbytes, 1]
                self.live += nbytes
                self.peak = max(self.peak, self.live)
            else:
                continue
            weakref.finalize(t, self._release, ptr)
        return out


def peak_memory_bytes(fn: Callable[[], object], device: torch.device | str = "cpu") -> int:
    """Peak bytes allocated by one call of ``fn`` above what was allocated before it (see the
    module docstring): ``torch.cuda.max_memory_allocated`` on CUDA, :class:`LiveTensorMemory`
    on the CPU."""
    device = torch.device(device)
    if device.type == "cuda":
        torch.cuda.synchronize(device)
        before = torch.cuda.memory_allocated(device)
        torch.cuda.reset_peak_memory_stats(device)
        fn()
        torch.cuda.synchronize(device)
        return int(torch.cuda.max_memory_allocated(device) - before)
    with LiveTensorMemory() as mem:
        fn()
    return mem.peak


# --------------------------------------------------------------------------- targets and formats


@dataclass(frozen=True)
class Target:
    """A performance target and the measured value.

    Attributes:
        name: What is measured, e.g. ``"ground median (small, CPU)"``.
        value: The measurement.
        limit: The target.
        unit: Unit shown after the numbers (``"ms"``, ``"x"``).
        higher_is_better: True for ``value >= limit`` targets (speed-ups), False for ``<=``.
    """

    name: str
    value: float
    limit: float
    unit: str
    higher_is_better: bool

    @property
    def met(self) -> bool:
        if math.isnan(self.value):
            return False
        return self.value >= self.limit if self.higher_is_better else self.value <= self.limit

    def describe(self) -> str:
        """E.g. ``"ground median: 41.2 ms (target <= 50 ms): met"``."""
        sign = ">=" if self.higher_is_better else "<="
        verdict = "met" if self.met else "**MISSED**"
        return (
            f"{self.name}: {_num(self.value)} {self.unit} (target {sign} {_num(self.limit)} "
            f"{self.unit}): {verdict}"
        )


def _num(x: float) -> str:
    if math.isnan(x) or math.isinf(x):
        return str(x)
    if abs(x) >= 100:
        return f"{x:,.0f}"
    if abs(x) >= 10:
        return f"{x:.1f}"
    return f"{x:.2f}"


def fmt_ms(ms: float) -> str:
    """Milliseconds with 3 significant digits (``"1,234"``, ``"12.3"``, ``"1.23"``)."""
    return _num(ms)


def fmt_ratio(x: float) -> str:
    """A ratio, e.g. ``"57.5x"``, ``"0.52x"``."""
    if math.isnan(x) or math.isinf(x):
        return "n/a"
    return f"{_num(x)}x"


def _scaled(value: float, base: float, units: Sequence[str]) -> str:
    i = 0
    while abs(value) >= base and i < len(units) - 1:
        value /= base
        i += 1
    text = f"{value:.0f}" if i == 0 else (f"{value:.3g}" if abs(value) < 1000 else f"{value:.0f}")
    return f"{text} {units[i]}".rstrip()


def fmt_count(n: float) -> str:
    """A count with a k/M/G suffix (``"648 k"``, ``"22.7 M"``)."""
    return _scaled(float(n), 1000.0, ("", "k", "M", "G", "T"))


def fmt_flops(n: float) -> str:
    """FLOPs with a unit (``"5.87 GFLOP"``)."""
    return _scaled(float(n), 1000.0, ("FLOP", "kFLOP", "MFLOP", "GFLOP", "TFLOP", "PFLOP"))


def fmt_bytes(n: float) -> str:
    """Bytes in binary units (``"56.3 MiB"``)."""
    return _scaled(float(n), 1024.0, ("B", "KiB", "MiB", "GiB", "TiB"))


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

    from scenes.calib import sensor_to_lidar, vod_lidar_calibration, vod_radar_calibration
    from scenes.synth import SynthSettings, synthesize

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


# --------------------------------------------------------------------------- command line


def command_line(module: str, argv: Sequence[str]) -> str:
    """The command that reproduces this run, e.g. ``python -m bench.latency --quick``."""
    return shlex.join(["python", "-m", module, *argv])


def bench_main(
    module: str,
    run: Callable[..., BenchResult],
    argv: Sequence[str] | None = None,
    description: str = "",
) -> int:
    """Command line shared by the benchmarks: ``[--quick] [--threads N] [--out-dir DIR]``.

    Sets torch's intra-op threads (default :data:`DEFAULT_THREADS`), runs ``run(quick=...,
    command=...)``, prints the Markdown and writes the JSON.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog=f"python -m {module}", description=description)
    parser.add_argument(
        "--quick", action="store_true", help="fewer repetitions and sizes (a smoke run)"
    )
    parser.add_argument(
        "--threads",
        type=int,
        default=DEFAULT_THREADS,
        help=f"torch intra-op CPU threads (default {DEFAULT_THREADS}, as the app's launch.py)",
    )
    parser.add_argument("--out-dir", type=Path, default=RESULTS_DIR, help="where the JSON goes")
    args = parser.parse_args(argv)
    if args.threads < 1:
        parser.error(f"--threads must be >= 1, got {args.threads}")
    torch.set_num_threads(args.threads)
    result = run(quick=args.quick, command=command_line(module, argv))
    print(result.to_markdown())
    path = write_result(result, args.out_dir)
    print(f"wrote {path}")
    return 0
