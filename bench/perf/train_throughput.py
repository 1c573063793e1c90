"""Training throughput: ``python -m bench.perf.train_throughput [--quick]``.

Samples per second of the training step of :mod:`model.training.loop` without its data loader: batches
of 4 synthetic samples (64-beam LiDAR, 5-scan radar, a generated prompt and its referents' boxes,
held in memory) go through target drawing (:func:`model.head.targets.draw_targets`),
``model.forward``, :func:`model.head.losses.grounding_loss`, backward, gradient clipping (max-norm 35)
and AdamW (lr 1e-3, weight decay 5e-4), as in :func:`model.training.loop.train`. The prompts repeat
(8 distinct prompts), so after the warm-up the frozen MiniLM serves them from its cache, as it
does from the second epoch of a real run. Reading files and augmentations are not included.

``small`` preset on the CPU (float32) with the benchmark's thread count (``--threads``, default
1) and, in fewer steps, with one thread per core (torch's default, what ``python -m model.train``
uses); with CUDA also ``small`` and ``paper`` on the GPU under bfloat16 autocast (what
``model.training.loop`` uses there).
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import asdict, dataclass

import torch

from bench.common import (
    BenchResult,
    SceneWorkload,
    Table,
    bench_main,
    bench_parser,
    fmt_ms,
    machine_info,
    summarize,
    synchronize,
    synthetic_scenes,
)
from model import build_model, collate_targets, draw_targets, grounding_loss

BATCH = 4
GRAD_CLIP = 35.0


@dataclass(frozen=True)
class StepTimes:
    """Milliseconds of one training step, by phase."""

    targets: float
    forward: float
    backward: float
    optimizer: float

    @property
    def total(self) -> float:
        return self.targets + self.forward + self.backward + self.optimizer


def samples_of(scenes: list[SceneWorkload]) -> list[tuple]:
    """``(lidar, radar, prompt, boxes, classes)`` of every prompt of ``scenes``."""
    return [
        (s.lidar, s.radar, p, b, c)
        for s in scenes
        for p, b, c in zip(s.prompts, s.boxes, s.classes, strict=True)
    ]


def train_steps(
    preset: str, samples: list[tuple], device: str, warmup: int, steps: int, amp: bool
) -> list[StepTimes]:
    """Time ``steps`` training steps after ``warmup`` untimed ones."""
    torch.manual_seed(0)
    model = build_model(preset).to(device).train()
    params = [p for p in model.parameters() if p.requires_grad]
    optimizer = torch.optim.AdamW(params, lr=1e-3, weight_decay=5e-4)
    dev = torch.device(device)
    times = []
    for step in range(warmup + steps):
        batch = [samples[(step * BATCH + i) % len(samples)] for i in range(BATCH)]
        synchronize(dev)
        t0 = time.perf_counter()
        targets = collate_targets(
            [draw_targets(b[3], b[4], model.head_grid, model.cfg.head) for b in batch]
        ).to(dev)
        t1 = time.perf_counter()
        with torch.autocast(device_type=dev.type, dtype=torch.bfloat16, enabled=amp):
            out = model([b[0] for b in batch], [b[1] for b in batch], [b[2] for b in batch])
        loss = grounding_loss(out, targets).total
        synchronize(dev)
        t2 = time.perf_counter()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        synchronize(dev)
        t3 = time.perf_counter()
        torch.nn.utils.clip_grad_norm_(params, GRAD_CLIP)
        optimizer.step()
        synchronize(dev)
        t4 = time.perf_counter()
        if not torch.isfinite(loss):
            raise RuntimeError(f"non-finite loss at step {step} ({preset}, {device})")
        if step >= warmup:
            ms = [(b - a) * 1000.0 for a, b in ((t0, t1), (t1, t2), (t2, t3), (t3, t4))]
            times.append(StepTimes(*ms))
    return times


def _threads(n: int) -> str:
    return f"{n} thread" if n == 1 else f"{n} threads"


def _rows(label: str, times: list[StepTimes]) -> tuple[str, ...]:
    total = summarize([t.total for t in times])
    mean_rate = BATCH * len(times) / (sum(t.total for t in times) / 1000.0)
    phase = {
        k: summarize([getattr(t, k) for t in times]).median
        for k in ("targets", "forward", "backward", "optimizer")
    }
    return (
        label,
        str(len(times)),
        f"{BATCH * 1000.0 / total.median:.2f}",
        f"{mean_rate:.2f}",
        fmt_ms(total.median),
        fmt_ms(phase["targets"]),
        fmt_ms(phase["forward"]),
        fmt_ms(phase["backward"]),
        fmt_ms(phase["optimizer"]),
    )


def run(quick: bool = False, command: str = "python -m bench.perf.train_throughput") -> BenchResult:
    """Time training steps (``quick``: 4 steps instead of 20)."""
    start = time.perf_counter()
    machine = machine_info(command)
    samples = samples_of(synthetic_scenes(4, prompts_per_world=2, seed=0))
    warmup, steps = (2, 4) if quick else (3, 20)
    threads = torch.get_num_threads()
    cores = os.cpu_count() or 1
    configs = [
        (
            f"`small`, CPU, float32, {_threads(threads)}",
            "small",
            "cpu",
            False,
            threads,
            warmup,
            steps,
        )
    ]
    if cores != threads:
        configs.append(
            (
                f"`small`, CPU, float32, {_threads(cores)}",
                "small",
                "cpu",
                False,
                cores,
                2,
                max(2, steps // 6),
            )
        )
    if torch.cuda.is_available():
        configs += [
            ("`small`, GPU, bfloat16 autocast", "small", "cuda", True, threads, warmup, steps),
            ("`paper`, GPU, bfloat16 autocast", "paper", "cuda", True, threads, warmup, steps),
        ]
    rows, data = [], {}
    for label, preset, device, amp, n_threads, n_warmup, n_steps in configs:
        torch.set_num_threads(n_threads)
        try:
            times = train_steps(preset, samples, device, n_warmup, n_steps, amp)
        finally:
            torch.set_num_threads(threads)
        rows.append(_rows(label, times))
        data[f"{preset}_{device}_{n_threads}threads"] = [asdict(t) for t in times]
    table = Table(
        title=f"Training step, batch {BATCH}",
        columns=(
            "preset, device",
            "steps",
            "samples/s (median step)",
            "samples/s (mean)",
            "step median ms",
            "targets ms",
            "forward + loss ms",
            "backward ms",
            "clip + AdamW ms",
        ),
        rows=tuple(rows),
    )
    findings = [
        f"{len(samples)} distinct synthetic samples (their prompts are in the text encoder's "
        "cache after the warm-up steps, as from a real run's second epoch); reading files and "
        "augmentations are not included.",
    ]
    if not torch.cuda.is_available():
        findings.append("No CUDA device on this machine: GPU rows were not measured.")
    return BenchResult(
        name="train_throughput",
        title="Training throughput",
        machine=machine,
        tables=(table,),
        findings=tuple(findings),
        data=data,
        seconds=time.perf_counter() - start,
    )


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.perf.train_throughput``'s parser (the shared flags only)."""
    return bench_parser("bench.perf.train_throughput", __doc__.splitlines()[0])


def main(argv: list[str] | None = None) -> int:
    return bench_main("bench.perf.train_throughput", run, argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    raise SystemExit(main())
