"""Cost of DGGF's graph against the static axial graph and a KNN graph:
``python -m bench.perf.graph_cost``.

On the same maps (the fused BEV maps ``lr_i`` of a synthetic scene, from an untrained model of
each preset, batch 1), in one process, the graph construction + max-relative aggregation of:

- **DGGF**: the dynamic axial graph of Algorithm 1 (:func:`model.nets.dggf.dynamic_max_relative`,
  roll step ``K`` = 8, 4, 2 per stage; edges where the feature distance is below ``mu - sigma``
  estimated from the diagonal quadrants);
- **GGF**: Talk2Radar's static axial graph (:func:`model.nets.dggf.static_max_relative`, ``K`` = 2,
  every roll is an edge);
- **KNN**: a Vision-GNN graph, :func:`knn_max_relative` below: exhaustive pairwise Euclidean
  distances between all ``H * W`` nodes, the ``k = 9`` nearest (the node itself included, as
  ViG), max over the neighbours of ``x_j - x_i``. The distance matrix is computed in chunks of
  4096 query nodes so that it fits in memory (the work is the same).

The whole DGGF block of the model (gate, CPE, graph, 1x1 conv, FFN) is timed beside them for
scale. Latency: median wall time over up to 10 calls, the variants of one stage called in alternation
(round-robin), a variant stopping after 3 s of calls; peak memory: bytes allocated by one call (see :mod:`bench.common`). "Distances" counts
the node-pair distances the method evaluates per map.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import torch
from torch import Tensor

from bench.common import (
    BenchResult,
    Table,
    Target,
    bench_main,
    bench_parser,
    fmt_bytes,
    fmt_count,
    fmt_ms,
    fmt_ratio,
    interleaved_ms,
    machine_info,
    peak_memory_bytes,
    summarize,
    synthetic_scenes,
)
from model import build_model, dynamic_max_relative, dynamic_max_relative_loop, static_max_relative

LOOP = dynamic_max_relative_loop
"""The roll-loop form of Algorithm 1 when model/nets/dggf.py has it beside the default form."""
LOOP_LABEL = "same graph, roll loop (`dynamic_max_relative_loop`)"

KNN_K = 9
KNN_CHUNK = 4096
SPEEDUP_TARGET = 10.0
BLOCK = "*whole DGGF block (gate, CPE, graph, FFN), for scale*"


def knn_max_relative(x: Tensor, k: int = KNN_K, chunk: int = KNN_CHUNK) -> Tensor:
    """Max-relative aggregation over a KNN graph (Vision GNN's ``MRConv`` with a dense KNN).

    Args:
        x: ``(B, C, H, W)`` feature map; every cell is a node, its channels the features.
        k: Neighbours per node, the node itself included (its distance is 0).
        chunk: Query nodes per block of the ``(chunk, H * W)`` distance matrix.

    Returns:
        ``(B, C, H, W)``: ``max_{j in kNN(i)} (x_j - x_i)`` per node ``i`` and channel
        (``>= 0`` since ``i`` is its own neighbour).
    """
    b, c, h, w = x.shape
    n = h * w
    if not 1 <= k <= n:
        raise ValueError(f"knn_max_relative: k must be in [1, {n}], got {k}")
    nodes = x.flatten(2).transpose(1, 2).contiguous()  # (B, N, C)
    squared = nodes.square().sum(dim=-1)  # (B, N)
    batch = torch.arange(b, device=x.device)[:, None, None]
    out = torch.empty_like(nodes)
    for start in range(0, n, chunk):
        query = nodes[:, start : start + chunk]  # (B, n, C)
        dist = (
            squared[:, start : start + chunk, None]
            - 2.0 * torch.matmul(query, nodes.transpose(1, 2))
            + squared[:, None, :]
        )  # (B, n, N) squared Euclidean distances
        idx = dist.topk(k, dim=-1, largest=False).indices  # (B, n, k)
        neighbours = nodes[batch, idx]  # (B, n, k, C)
        out[:, start : start + chunk] = (neighbours - query[:, :, None]).amax(dim=2)
    return out.transpose(1, 2).reshape(b, c, h, w)


@dataclass(frozen=True)
class Result:
    """Cost of one graph at one stage (latency median in ms, peak bytes, distances per map)."""

    latency_ms: float
    runs: int
    memory: int
    distances: int


def measure_all(
    calls: dict[str, Callable[[], object]],
    distances: dict[str, int],
    rounds: int,
    budget_s: float,
) -> dict[str, Result]:
    """Peak memory of one call of each, a warm-up call for the fast ones, then the latencies
    timed in alternation (:func:`bench.common.interleaved_ms`)."""
    memory = {}
    for label, fn in calls.items():
        t0 = time.perf_counter()
        memory[label] = peak_memory_bytes(fn)
        if time.perf_counter() - t0 < 2.0:
            fn()
    samples = interleaved_ms(calls, rounds, budget_s)
    return {
        label: Result(
            summarize(samples[label]).median,
            len(samples[label]),
            memory[label],
            distances[label],
        )
        for label in calls
    }


def axial_shifts(height: int, width: int, k: int) -> int:
    """Rolls of the axial graph with step ``k``: ``m k < H`` down, ``m k < W`` right."""
    return len(range(k, height, k)) + len(range(k, width, k))


def preset_maps(name: str) -> tuple[list[Tensor], object]:
    """The fused maps ``lr_1..3`` of an untrained ``name`` model on a synthetic scene, and the
    model (for its DGGF blocks)."""
    torch.manual_seed(0)
    model = build_model(name).eval()
    scene = synthetic_scenes(1, 1, seed=0)[0]
    return list(model.encode_scene(scene.lidar, scene.radar).stages), model


def run(quick: bool = False, command: str = "python -m bench.perf.graph_cost") -> BenchResult:
    """Measure the three graphs on both presets' stages (``quick``: KNN only up to 80 x 80)."""
    start = time.perf_counter()
    machine = machine_info(command)
    rounds, budget_s = (3, 1.0) if quick else (10, 3.0)
    tables, data, targets = [], {}, []
    loop_ratios: list[tuple[str, float, float]] = []
    loop_vs_knn: list[str] = []
    tokens = torch.randn(1, 12, 384, generator=torch.Generator().manual_seed(2))
    mask = torch.zeros(1, 12, dtype=torch.bool)
    for name in ("paper", "small"):
        maps, model = preset_maps(name)
        graph_k = model.cfg.text_fusion.graph_k
        ggf_k = model.cfg.text_fusion.ggf_k
        for i, x in enumerate(maps):
            _, c, h, w = x.shape
            n = h * w
            k = graph_k[i]
            block = model.grounding.text_fusion[i]
            text = tokens[..., : model.text_encoder.out_dim]
            dggf_label = f"DGGF dynamic axial graph, K = {k}"
            knn_label = f"KNN graph, k = {KNN_K}"

            def no_grad(fn: Callable[[], object]) -> Callable[[], object]:
                def wrapped() -> object:
                    with torch.no_grad():
                        return fn()

                return wrapped

            calls = {dggf_label: no_grad(lambda x=x, k=k: dynamic_max_relative(x, k))}
            distances = {dggf_label: n * (axial_shifts(h, w, k) + 1)}
            if LOOP is not None:
                calls[LOOP_LABEL] = no_grad(lambda x=x, k=k: LOOP(x, k))
                distances[LOOP_LABEL] = distances[dggf_label]
            ggf_label = f"GGF static axial graph, K = {ggf_k}"
            calls[ggf_label] = no_grad(lambda x=x, g=ggf_k: static_max_relative(x, g))
            distances[ggf_label] = 0
            skip_knn = quick and n > 10_000
            if not skip_knn:
                calls[knn_label] = no_grad(lambda x=x: knn_max_relative(x))
            distances[knn_label] = n * n
            calls[BLOCK] = no_grad(lambda b=block, x=x, t=text: b(x, t, mask))
            distances[BLOCK] = 0
            rows = measure_all(calls, distances, rounds, budget_s)
            if skip_knn:
                rows[knn_label] = Result(math.nan, 0, -1, n * n)
            rows = {label: rows[label] for label in distances}
            block_result = rows.pop(BLOCK)
            dggf = next(iter(rows.values()))
            table_rows = []
            for label, r in rows.items():
                ran = not math.isnan(r.latency_ms)
                table_rows.append(
                    (
                        label,
                        f"{fmt_ms(r.latency_ms)} ({r.runs})" if ran else "not run (--quick)",
                        fmt_bytes(r.memory) if r.memory >= 0 else "-",
                        fmt_count(r.distances) if r.distances else "0 (fixed edges)",
                        fmt_ratio(r.latency_ms / dggf.latency_ms) if ran else "-",
                        fmt_ratio(r.memory / dggf.memory) if ran and dggf.memory > 0 else "-",
                    )
                )
            table_rows.append(
                (
                    BLOCK,
                    f"{fmt_ms(block_result.latency_ms)} ({block_result.runs})",
                    fmt_bytes(block_result.memory),
                    "",
                    fmt_ratio(block_result.latency_ms / dggf.latency_ms),
                    fmt_ratio(block_result.memory / dggf.memory) if dggf.memory > 0 else "-",
                )
            )
            tables.append(
                Table(
                    title=f"`{name}` stage {i + 1}: {h} x {w} nodes, C = {c}, CPU",
                    columns=(
                        "graph + max-relative aggregation",
                        "latency ms (runs)",
                        "peak memory",
                        "distances",
                        "latency / DGGF",
                        "memory / DGGF",
                    ),
                    rows=tuple(table_rows),
                )
            )
            data[f"{name}_stage{i + 1}"] = {
                "size": [c, h, w],
                "graphs": {label: asdict(r) for label, r in rows.items()},
                "dggf_block": asdict(block_result),
            }
            if LOOP_LABEL in rows:
                loop = rows[LOOP_LABEL]
                loop_ratios.append(
                    (
                        f"`{name}` {h} x {w}",
                        dggf.latency_ms / loop.latency_ms,
                        dggf.memory / max(loop.memory, 1),
                    )
                )
            if i == 0 and LOOP_LABEL in rows:
                loop_vs_knn.append(
                    f"`{name}` stage 1: {fmt_ratio(rows[knn_label].latency_ms / loop.latency_ms)}"
                )
            if i == 0:
                knn = rows[knn_label]
                targets.append(
                    Target(
                        f"KNN / DGGF graph latency, `{name}` stage 1 ({h} x {w})",
                        knn.latency_ms / dggf.latency_ms,
                        SPEEDUP_TARGET,
                        "x",
                        True,
                    )
                )
    findings = [t.describe() for t in targets]
    findings.append(
        "Maps: the fused BEV maps of one synthetic scene (untrained model of each preset), so "
        "the sparsity of a real BEV map (most cells empty) is kept."
    )
    if loop_ratios:
        parts = ", ".join(
            f"{where} {fmt_ratio(lat)} time, {fmt_ratio(mem)} memory"
            for where, lat, mem in loop_ratios
        )
        findings.append(
            "`dynamic_max_relative` (the model's default form) against the roll loop of the same "
            f"graph, inference without gradients: {parts}. Same values (model/nets/dggf.py); a ratio "
            "above 1 means the loop is the faster form for `ground`. KNN / roll-loop latency: "
            + ", ".join(loop_vs_knn)
            + "."
        )
    data["targets"] = [asdict(t) for t in targets]
    return BenchResult(
        name="graph_cost",
        title="Graph cost: DGGF's dynamic axial graph against GGF and KNN",
        machine=machine,
        tables=tuple(tables),
        findings=tuple(findings),
        data=data,
        seconds=time.perf_counter() - start,
    )


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.perf.graph_cost``'s parser (the shared flags only)."""
    return bench_parser("bench.perf.graph_cost", __doc__.splitlines()[0])


def main(argv: list[str] | None = None) -> int:
    return bench_main("bench.perf.graph_cost", run, argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    raise SystemExit(main())
