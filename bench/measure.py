"""Measurement helpers of the benchmarks.

- Wall-clock times in milliseconds (:func:`time_ms`, :func:`interleaved_ms`), CUDA synchronised
  before every reading; summarised by :func:`summarize` (median, p90 with linear interpolation
  between order statistics, mean, min, max).
- FLOPs with :class:`torch.utils.flop_counter.FlopCounterMode` (:func:`count_flops`): it counts
  matrix products and convolutions only (2 FLOPs per multiply-add; element-wise ops, softmax and
  pooling are not counted), per module and in total; a fused attention counts as its two matrix
  products.
- Peak memory (:func:`peak_memory_bytes`): the peak, during one call, of the bytes of tensors
  allocated *by that call* and still alive (inputs and parameters are not counted; outputs are).
  On CUDA ``torch.cuda.max_memory_allocated`` minus the allocation before the call; on the CPU the
  same quantity tracked per tensor storage by :class:`LiveTensorMemory` (a ``TorchDispatchMode``;
  ``tracemalloc`` does not see torch's allocations and the process RSS does not shrink when glibc
  keeps freed pages). Scratch buffers private to a CPU kernel are not seen.
"""

from __future__ import annotations

import math
import time
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_flatten
from torch.utils.flop_counter import FlopCounterMode, sdpa_flop_count

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


def _cpu_attention_flops(
    query_shape: tuple[int, ...], key_shape: tuple[int, ...], value_shape: tuple[int, ...], *_, **__
) -> int:
    """FLOPs of one fused attention from its operands' shapes (as ``FlopCounterMode``'s own)."""
    return sdpa_flop_count(query_shape, key_shape, value_shape)


def _onednn_linear_flops(
    input_shape: tuple[int, ...], weight_shape: tuple[int, ...], *_, **__
) -> int:
    """FLOPs of oneDNN's linear ``(..., K) x (N, K)^T``: those of the matrix product."""
    return 2 * math.prod(input_shape[:-1]) * weight_shape[0] * weight_shape[1]


_EXTRA_FLOP_FORMULAS = {
    torch.ops.aten._scaled_dot_product_flash_attention_for_cpu: _cpu_attention_flops,
    **(
        {torch.ops.mkldnn._linear_pointwise: _onednn_linear_flops}
        if hasattr(torch.ops.mkldnn, "_linear_pointwise")
        else {}
    ),
}
"""Operators ``FlopCounterMode`` has no formula for: the CPU kernel of
``scaled_dot_product_attention`` counts as the attention it computes (``q k^T`` and the product
with ``v``: the FLOPs of the explicit form), oneDNN's linear (``model.text``) as its matrix
product, so that a fused or oneDNN form of an operation has the same floor as the plain one."""


@dataclass(frozen=True)
class FlopCount:
    """FLOPs of one call: ``total`` and per module (fully qualified names as FlopCounterMode
    reports them, e.g. ``"TPCNet.scene.lidar.pillars"``; ``"Global"`` is the total)."""

    total: int
    by_module: dict[str, int]


def count_flops(fn: Callable[[], object]) -> FlopCount:
    """FLOPs of ``fn()`` counted by ``FlopCounterMode`` (matmuls and convolutions, 2 per MAC).

    Run it on meta tensors (module ``.to("meta")`` and ``torch.empty(..., device="meta")`` inputs)
    to count a call that would be too slow or too large to execute.
    """
    with FlopCounterMode(display=False, custom_mapping=_EXTRA_FLOP_FORMULAS) as counter:
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
