"""Cost of the LiDAR-radar fusions (the paper's table VI): ``python -m bench.perf.fusion_cost``.

For each backbone stage size of the ``paper`` preset (160 x 160 x 64, 80 x 80 x 128, 40 x 40 x 256,
4 heads) and of the ``small`` preset (80 x 80 x 32, 40 x 40 x 48, 20 x 20 x 64, 1 head), in one
process: parameters, FLOPs, peak memory and latency of one fusion module (batch 1, eval mode, no
gradient) for BACA with 8 x 8, 12 x 12, 16 x 16 and 18 x 18 agents, bi_mhca (vanilla bidirectional
cross attention as the model computes it, in query chunks of ``FusionConfig.mhca_chunk``; and
unchunked, all queries at once as the paper's Bi-MHCA), lidar_query, radar_query (one direction of
BACA, 12 x 12) and conv_gate; ratios are to BACA 12 x 12 at the same size (``> 1``: the method
costs more than BACA).

- FLOPs: ``FlopCounterMode`` on meta tensors (matmuls and convs, 2 per multiply-add; exact for
  every size, nothing is executed).
- Peak memory: bytes allocated by the call above what existed before (see :mod:`bench.common`);
  one call.
- Latency: median wall time over up to 10 calls, the methods of one size called in alternation
  (round-robin) so that a change of the machine's load hits them alike; a method stops after 2 s
  of calls (at least one). The memory run (and one more call when it is fast) is the warm-up; a
  call of more than 10 s (bi_mhca at 160 x 160 on a CPU) is run once, its memory run timed.

bi_mhca is executed only where its attention scores fit in half of the available memory; where it
does not, its FLOPs are still given and the table says it did not run. With CUDA the same is
measured on the GPU.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import asdict, dataclass

import torch
from torch import nn

from bench.common import (
    BenchResult,
    Table,
    Target,
    bench_main,
    bench_parser,
    count_flops,
    count_params,
    fmt_bytes,
    fmt_count,
    fmt_flops,
    fmt_ms,
    fmt_ratio,
    interleaved_ms,
    machine_info,
    peak_memory_bytes,
    summarize,
)
from model import FusionConfig, build_fusion, preset

REFERENCE = "BACA 12x12"
UNCHUNKED = "bi_mhca, unchunked"
SLOW_CALL_S = 10.0
"""A call longer than this is run once only (its memory run is its timing)."""
FLOP_TARGET, LATENCY_TARGET, MEMORY_TARGET = 50.0, 20.0, 20.0


@dataclass(frozen=True)
class Size:
    """One fusion input size: ``(1, channels, height, width)`` per sensor."""

    preset: str
    stage: int
    channels: int
    height: int
    width: int
    heads: int
    chunk: int

    @property
    def label(self) -> str:
        return (
            f"`{self.preset}` stage {self.stage}: {self.height} x {self.width} cells, "
            f"C = {self.channels}, {self.heads} head{'s' if self.heads > 1 else ''}"
        )


@dataclass(frozen=True)
class Method:
    """A fusion variant as a :class:`FusionConfig` (heads from the preset).

    Attributes:
        unchunked: bi_mhca only: one chunk of all ``L`` queries (the vanilla attention of the
            paper's Bi-MHCA) instead of the preset's ``mhca_chunk``.
    """

    label: str
    kind: str
    agent_size: tuple[int, int] = (12, 12)
    unchunked: bool = False


METHODS = (
    Method("BACA 8x8", "baca", (8, 8)),
    Method(REFERENCE, "baca", (12, 12)),
    Method("BACA 16x16", "baca", (16, 16)),
    Method("BACA 18x18", "baca", (18, 18)),
    Method("bi_mhca", "bi_mhca"),
    Method(UNCHUNKED, "bi_mhca", unchunked=True),
    Method("lidar_query 12x12", "lidar_query"),
    Method("radar_query 12x12", "radar_query"),
    Method("conv_gate", "conv_gate"),
)


@dataclass(frozen=True)
class Measurement:
    """Cost of one method at one size (``latency_ms``/``memory`` NaN/-1 when it did not run)."""

    params: int
    flops: int
    latency_ms: float
    latency_runs: int
    memory: int
    note: str = ""


def stage_sizes(name: str) -> list[Size]:
    """The three backbone stage sizes of preset ``name``."""
    cfg = preset(name)
    ny, nx = cfg.pillars.grid.shape
    return [
        Size(name, i + 1, c, ny // s, nx // s, cfg.fusion.heads, cfg.fusion.mhca_chunk)
        for i, (c, s) in enumerate(
            zip(cfg.backbone.channels, cfg.backbone.cumulative_strides, strict=True)
        )
    ]


def build(method: Method, size: Size) -> nn.Module:
    """The fusion module of ``method`` for ``size`` (eval mode, CPU, seeded)."""
    torch.manual_seed(0)
    cfg = FusionConfig(
        kind=method.kind,
        agent_size=method.agent_size,
        heads=size.heads,
        mhca_chunk=chunk_of(method, size),
    )
    return build_fusion(cfg, size.channels).eval()


def chunk_of(method: Method, size: Size) -> int:
    """Queries per bi_mhca chunk: all ``L`` cells when unchunked, else the preset's."""
    return size.height * size.width if method.unchunked else size.chunk


def _available_bytes() -> int:
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError):
        pass
    return 8 * 1024**3


def attention_bytes(size: Size, chunk: int) -> int:
    """Bytes of bi_mhca's largest live attention tensors: raw and scaled scores of one query
    chunk (``heads x chunk x L`` float32 each)."""
    cells = size.height * size.width
    return 2 * size.heads * min(chunk, cells) * cells * 4


def measure_size(
    size: Size, device: str, rounds: int, budget_s: float, memory_budget: int | None
) -> dict[str, Measurement]:
    """Parameters, FLOPs (meta), peak memory and latency of every method at ``size``.

    ``memory_budget``: bi_mhca runs only when :func:`attention_bytes` is below it (None: never,
    the ``--quick`` case). Latency: after one memory run (and one warm-up call for calls of
    less than 2 s), :func:`bench.common.interleaved_ms` over ``rounds`` rounds.
    """
    shape = (1, size.channels, size.height, size.width)
    gen = torch.Generator().manual_seed(1)
    f_l = torch.randn(shape, generator=gen).to(device)
    f_r = torch.randn(shape, generator=gen).to(device)
    x_meta = torch.empty(shape, device="meta")
    static: dict[str, tuple[int, int, int, str]] = {}
    calls = {}
    slow: dict[str, list[float]] = {}
    for method in METHODS:
        module = build(method, size)
        params = count_params(module)
        meta = build(method, size).to("meta")
        with torch.no_grad():
            flops = count_flops(lambda meta=meta: meta(x_meta, x_meta)).total
        if method.kind == "bi_mhca" and memory_budget is None:
            static[method.label] = (params, flops, -1, "not run (--quick)")
            continue
        need_bytes = attention_bytes(size, chunk_of(method, size))
        if method.kind == "bi_mhca" and need_bytes > memory_budget:
            need = fmt_bytes(need_bytes)
            static[method.label] = (params, flops, -1, f"not run: needs about {need}")
            continue
        module = module.to(device)

        def call(module: nn.Module = module) -> None:
            with torch.no_grad():
                module(f_l, f_r)

        t0 = time.perf_counter()
        memory = peak_memory_bytes(call, device)
        first = time.perf_counter() - t0
        if first > SLOW_CALL_S:
            # One call is all the budget allows: the memory run's own time is the sample (the
            # tracking costs microseconds per op, nothing next to a call this long).
            static[method.label] = (params, flops, memory, "timed during the memory run")
            slow[method.label] = [first * 1000.0]
            continue
        if first < 2.0:
            call()
        static[method.label] = (params, flops, memory, "")
        calls[method.label] = call
    samples = {**interleaved_ms(calls, rounds, budget_s, device), **slow} if calls else slow
    out = {}
    for method in METHODS:
        params, flops, memory, note = static[method.label]
        times = samples.get(method.label, [])
        latency = summarize(times).median if times else math.nan
        out[method.label] = Measurement(params, flops, latency, len(times), memory, note)
    return out


def _ratio(value: float, ref: float) -> float:
    if ref <= 0 or math.isnan(value) or value < 0 or math.isnan(ref):
        return math.nan
    return value / ref


def size_table(size: Size, results: dict[str, Measurement], device: str) -> Table:
    ref = results[REFERENCE]
    rows = []
    for method in METHODS:
        m = results[method.label]
        ran = not math.isnan(m.latency_ms)
        rows.append(
            (
                f"**{method.label}**" if method.label == REFERENCE else method.label,
                fmt_count(m.params),
                fmt_flops(m.flops),
                f"{fmt_ms(m.latency_ms)} ({m.latency_runs}{', ' + m.note if m.note else ''})"
                if ran
                else m.note,
                fmt_bytes(m.memory) if m.memory >= 0 else "-",
                fmt_ratio(_ratio(m.params, ref.params)),
                fmt_ratio(_ratio(m.flops, ref.flops)),
                fmt_ratio(_ratio(m.latency_ms, ref.latency_ms)),
                fmt_ratio(_ratio(m.memory, ref.memory)),
            )
        )
    return Table(
        title=f"{size.label}, {device.upper()}",
        columns=(
            "method",
            "params",
            "FLOPs",
            "latency ms (runs)",
            "peak memory",
            "params / BACA12",
            "FLOPs / BACA12",
            "latency / BACA12",
            "memory / BACA12",
        ),
        rows=tuple(rows),
    )


def run_device(
    sizes: list[Size], device: str, rounds: int, budget_s: float, skip_big: bool
) -> tuple[list[Table], dict, dict[Size, dict[str, Measurement]]]:
    """Every size on ``device``: tables, raw data and the measurements."""
    budget = _available_bytes() // 2 if device == "cpu" else torch.cuda.mem_get_info()[0] // 2
    all_results: dict[Size, dict[str, Measurement]] = {}
    tables, data = [], {}
    for size in sizes:
        limit = None if (skip_big and size.height * size.width > 10_000) else budget
        results = measure_size(size, device, rounds, budget_s, limit)
        all_results[size] = results
        tables.append(size_table(size, results, device))
        data[f"{size.preset}_stage{size.stage}"] = {
            "size": [size.channels, size.height, size.width],
            "heads": size.heads,
            "methods": {k: asdict(v) for k, v in results.items()},
        }
    return tables, data, all_results


def _unchunked_memory(size: Size, r: dict[str, Measurement]) -> tuple[float, bool]:
    """bi_mhca's unchunked peak (measured, or the attention-score estimate when it did not run)
    relative to BACA 12x12, and whether it was measured."""
    u, b = r[UNCHUNKED], r[REFERENCE]
    if u.memory >= 0:
        return _ratio(u.memory, b.memory), True
    return _ratio(attention_bytes(size, size.height * size.width), b.memory), False


def _summary(results: dict[Size, dict[str, Measurement]], device: str) -> Table:
    rows = []
    for size, r in results.items():
        b, m = r[REFERENCE], r["bi_mhca"]
        unchunked, measured = _unchunked_memory(size, r)
        rows.append(
            (
                f"`{size.preset}` {size.height} x {size.width} x {size.channels}",
                fmt_ratio(_ratio(m.flops, b.flops)),
                fmt_ratio(_ratio(m.latency_ms, b.latency_ms)),
                fmt_ratio(_ratio(m.memory, b.memory)),
                fmt_ratio(unchunked) + ("" if measured else " (estimate)"),
                fmt_ratio(_ratio(r["conv_gate"].latency_ms, b.latency_ms)),
            )
        )
    return Table(
        title=f"Summary: bi_mhca and conv_gate relative to BACA 12x12, {device.upper()}",
        columns=(
            "stage size",
            "bi_mhca FLOPs",
            "bi_mhca latency",
            "bi_mhca memory (chunked)",
            "bi_mhca memory (unchunked)",
            "conv_gate latency",
        ),
        rows=tuple(rows),
        notes=(
            "Chunked: the model's bi_mhca, queries in chunks of `FusionConfig.mhca_chunk`; "
            "unchunked: all queries at once, as the paper's Bi-MHCA (an estimate = its two "
            "`heads x L x L` float32 score tensors, where it was not run). On CUDA the model "
            "uses the fused `scaled_dot_product_attention` for both, which never holds the "
            "scores.",
        ),
    )


def run(quick: bool = False, command: str = "python -m bench.perf.fusion_cost") -> BenchResult:
    """Measure every method at every size (``quick``: bi_mhca not run above 100 x 100 cells)."""
    start = time.perf_counter()
    machine = machine_info(command)
    sizes = stage_sizes("paper") + stage_sizes("small")
    rounds, budget_s = (3, 1.0) if quick else (10, 2.0)
    tables, cpu_data, results = run_device(sizes, "cpu", rounds, budget_s, quick)
    tables.insert(0, _summary(results, "cpu"))
    first = results[sizes[0]]
    b, m = first[REFERENCE], first["bi_mhca"]
    targets = [
        Target(
            "bi_mhca / BACA 12x12 FLOPs at 160 x 160",
            _ratio(m.flops, b.flops),
            FLOP_TARGET,
            "x",
            True,
        ),
        Target(
            "bi_mhca / BACA 12x12 latency at 160 x 160 (CPU)",
            _ratio(m.latency_ms, b.latency_ms),
            LATENCY_TARGET,
            "x",
            True,
        ),
        Target(
            "bi_mhca / BACA 12x12 peak memory at 160 x 160 (CPU)",
            _ratio(m.memory, b.memory),
            MEMORY_TARGET,
            "x",
            True,
        ),
    ]
    findings = [t.describe() for t in targets]
    unchunked, measured = _unchunked_memory(sizes[0], first)
    findings.append(
        f"The model's bi_mhca splits its queries into chunks of {sizes[0].chunk} "
        "(`FusionConfig.mhca_chunk`), which bounds its memory by design; unchunked, as the "
        f"paper's Bi-MHCA, it needs {fmt_ratio(unchunked)} BACA 12x12's peak at 160 x 160 "
        + ("(measured)." if measured else "(estimate from its score tensors; too big to run here).")
    )
    if math.isnan(m.latency_ms):
        both = [s for s in sizes if not math.isnan(results[s]["bi_mhca"].latency_ms)]
        biggest = max(both, key=lambda s: s.height * s.width, default=None)
        where = biggest.label if biggest else "none"
        findings.append(
            f"bi_mhca did not run at 160 x 160 on this machine ({m.note}); the largest size at "
            f"which both ran: {where}. The FLOP ratio at 160 x 160 is exact (counted on meta "
            "tensors)."
        )
    findings.append(
        "Latency counts the whole fusion module (positional encoding, projections, attention, "
        "residual, 1x1 merge conv + BN + ReLU); memory is the peak of tensors allocated by one "
        "call (inputs and weights excluded)."
    )
    data: dict = {"cpu": cpu_data}
    if torch.cuda.is_available():
        gpu_tables, gpu_data, gpu_results = run_device(sizes, "cuda", rounds, budget_s, False)
        tables += [_summary(gpu_results, "cuda"), *gpu_tables]
        data["cuda"] = gpu_data
    else:
        findings.append("No CUDA device on this machine: GPU columns were not measured.")
    data["targets"] = [asdict(t) for t in targets]
    return BenchResult(
        name="fusion_cost",
        title="Fusion cost: BACA against cross attention and a convolutional gate (table VI)",
        machine=machine,
        tables=tuple(tables),
        findings=tuple(findings),
        data=data,
        seconds=time.perf_counter() - start,
    )


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.perf.fusion_cost``'s parser (the shared flags only)."""
    return bench_parser("bench.perf.fusion_cost", __doc__.splitlines()[0])


def main(argv: list[str] | None = None) -> int:
    return bench_main("bench.perf.fusion_cost", run, argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    raise SystemExit(main())
