"""Benchmark results and their rendering: where a benchmark ran (:class:`Machine`), its Markdown
:class:`Table` s, :class:`Target` s and findings (:class:`BenchResult`), the JSON files in
``bench/results/`` (:func:`write_result`, :func:`read_result`) and the number formats of the tables.

``docs/PERFORMANCE.md`` is written from those JSON files by :mod:`bench.run_all`
(:meth:`BenchResult.to_markdown`). Nothing here measures anything (see :mod:`bench.measure`).
"""

from __future__ import annotations

import datetime as dt
import json
import math
import os
import platform
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch

from scenes.utils.durable import atomic_write_text
from scenes.utils.textfile import read_text_file

REPO = Path(__file__).resolve().parents[1]
RESULTS_DIR = REPO / "bench" / "results"
PERFORMANCE_DOC = REPO / "docs" / "PERFORMANCE.md"
SCHEMA = "talk2pc-bench/1"


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
    atomic_write_text(path, json.dumps(result.to_json(), indent=1, allow_nan=True) + "\n")
    return path


def read_result(path: Path) -> BenchResult:
    """Read a file written by :func:`write_result`."""
    try:
        data = json.loads(read_text_file(path, "bench result", BenchResultError))
    except json.JSONDecodeError as exc:
        raise BenchResultError(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})") from exc
    return result_from_json(data, str(path))


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
