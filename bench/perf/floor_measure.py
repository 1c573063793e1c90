"""Measurements of :mod:`bench.perf.floor`: the machine's matmul rate, the FLOPs of each stage, and the
timed calls, each beside the rate measured just before it.

- Machine rate: :func:`matmul_rate`, GFLOP/s of a dense ``1024 x 1024`` float32 ``torch.mm``
  (``2 * 1024**3`` FLOPs), the median of a few calls; measured again before *every* timed call,
  so that each call is compared with the rate the machine gave at that moment (its cores are
  shared with other jobs).
- FLOPs: :func:`bench.measure.count_flops` (``torch.utils.flop_counter``: matrix products,
  convolutions and attention; element-wise work, pooling and softmax count 0) of the calls that
  are timed, in their module form: ``encode_scene`` as the scene encoder's ``detect`` with
  gradients on, split by stage through the modules that run it, and ``ground``
  of the referent path as its two networks, the text encoder (every prompt new to it) and the
  referent stage (counted in its module form: PyTorch's fused attention fast path, which its
  inference may take, hides its attention from the counter).
- The floor of a call is ``FLOPs / rate``; its ratio is ``time / floor``. The ratios of a call
  use the rate measured just before it; medians are taken over calls.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from bench.measure import count_flops
from bench.perf.latency_measure import DETECT_PARTS, REFERENT, measure_detect_parts, text_cache
from bench.perf.model_parts import model_parts
from bench.perf.vod_frames import VodFrame
from bench.workloads import SceneWorkload
from model import SceneFeatures, TPCNet

MATMUL_N = 1024
"""Side of the square float32 matmul that measures the machine's rate."""
ENCODE_STAGES = ("pillars", "backbone", "fusion", "detect")
"""``SceneTimings`` fields of ``encode_scene`` (referent path)."""
GROUND_STAGES = REFERENT.ground_stages
"""``GroundTimings`` fields of ``ground`` (referent path): text, referent, decode (the answer)."""


def matmul_rate(calls: int = 5, n: int = MATMUL_N) -> float:
    """GFLOP/s of a dense ``n x n`` float32 ``torch.mm`` (median of ``calls`` after one warm-up)."""
    a = torch.randn(n, n)
    b = torch.randn(n, n)
    out = torch.empty(n, n)
    torch.mm(a, b, out=out)
    times = []
    for _ in range(calls):
        t0 = time.perf_counter()
        torch.mm(a, b, out=out)
        times.append(time.perf_counter() - t0)
    return 2.0 * n**3 / float(np.median(times)) / 1e9


def _module_names(*modules: torch.nn.Module | None) -> set[str]:
    return {type(m).__name__ for m in modules if m is not None}


def encode_flops(model: TPCNet, frame: VodFrame) -> dict[str, int]:
    """FLOPs of ``model.encode_scene(frame)`` per :data:`ENCODE_STAGES` plus ``total`` and the
    detection stage's ``neck`` and ``head`` (its decoding and candidate description count 0).

    Counted on the scene encoder's module form, ``model.detect`` with gradients on (as training
    runs it), so that every implementation of ``encode_scene`` has one floor: its inference
    fast paths compute the same functions with these FLOPs (a compiled pass, such as the
    pillars' :mod:`model.nets.pillar_kernel`, runs outside the counter's sight). The candidates'
    pooling, a few thousand FLOPs, is left out. Stages are told apart by the classes of the
    modules that run them (``FlopCounterMode`` reports per module); FLOPs outside every named
    module go to ``detect``.
    """
    lidar = model.scene.clouds([frame.lidar], 1, "lidar")
    radar = model.scene.clouds([frame.radar], 1, "radar")
    with torch.enable_grad():
        counted = count_flops(lambda: model.detect(lidar, radar))
    parts = model_parts(model)
    branches = [b for b in (parts.lidar, parts.radar) if b is not None]
    stage_of: dict[str, str] = {}
    for name in _module_names(*(b.pillars for b in branches)):
        stage_of[name] = "pillars"
    for name in _module_names(*(b.backbone for b in branches)):
        stage_of[name] = "backbone"
    for name in _module_names(*(parts.fusion or [])):
        stage_of[name] = "fusion"
    out = dict.fromkeys(ENCODE_STAGES, 0)
    tops = {k: v for k, v in counted.by_module.items() if "." not in k and k != "Global"}
    for name, flops in tops.items():
        out[stage_of.get(name, "detect")] += flops
    out["detect"] += counted.total - sum(tops.values())
    out["neck"] = tops.get(type(parts.neck).__name__, 0)
    out["head"] = tops.get(type(parts.head).__name__, 0)
    out["total"] = counted.total
    return out


def ground_flops(model: TPCNet, features: SceneFeatures, prompt: str) -> dict[str, int]:
    """FLOPs of ``model.ground(features, prompt)`` for a prompt new to the text encoder:
    ``text`` (MiniLM), ``referent`` (the referent stage), ``decode`` (0: ranking and heatmap),
    ``total``."""
    objects = features.objects
    assert objects is not None, "the floor benchmark needs the referent path"
    old = text_cache(model, 0)
    try:
        with torch.no_grad():
            text = model.text_encoder([prompt])
            text_flops = count_flops(lambda: model.text_encoder([prompt])).total
            # Counted on the stage's module form (gradients on: no fused fast path, whose
            # attention the counter does not see), so that every implementation has one floor.
            with torch.enable_grad():
                refer = model_parts(model).refer
                ref = count_flops(lambda: refer(objects, text)).total if len(objects) else 0
    finally:
        text_cache(model, old)
    return {"text": text_flops, "referent": ref, "decode": 0, "total": text_flops + ref}


@dataclass(frozen=True)
class TimedCall:
    """One timed call.

    Attributes:
        kind: ``"encode"`` (``encode_scene``) or ``"ground"`` (``ground`` of a new prompt).
        frame: The frame's id.
        rate: GFLOP/s of :func:`matmul_rate` just before the call.
        wall_ms: Wall-clock milliseconds of the call.
        stages: The model's own stage timings (ms) of the call.
        flops: FLOPs of the call per stage, and ``total``.
    """

    kind: str
    frame: str
    rate: float
    wall_ms: float
    stages: dict[str, float]
    flops: dict[str, int]

    def floor_ms(self, stage: str = "total") -> float:
        """Milliseconds the FLOPs of ``stage`` take at :attr:`rate`."""
        return self.flops.get(stage, 0) / (self.rate * 1e9) * 1e3

    def ratio(self, stage: str = "total") -> float:
        """Time over floor of the call (``total``: wall clock) or of one stage (nan: no FLOPs)."""
        floor = self.floor_ms(stage)
        if floor <= 0:
            return float("nan")
        ms = self.wall_ms if stage == "total" else self.stages[stage]
        return ms / floor


@dataclass
class FloorRun:
    """Everything :func:`measure` records."""

    calls: list[TimedCall] = field(default_factory=list)
    detect_parts: dict[str, list[float]] = field(default_factory=dict)
    detect_rates: list[float] = field(default_factory=list)
    candidates: list[int] = field(default_factory=list)

    def of(self, kind: str) -> list[TimedCall]:
        return [c for c in self.calls if c.kind == kind]


def _timed(fn: Callable[[], object]) -> tuple[object, float]:
    t0 = time.perf_counter()
    out = fn()
    return out, (time.perf_counter() - t0) * 1000.0


def measure(
    models: dict[str, TPCNet],
    frames: list[VodFrame],
    repeats: int,
    prompts: int,
    progress: bool = True,
) -> dict[str, FloorRun]:
    """``repeats`` rounds over ``frames``: per frame ``encode_scene``, then ``ground`` of up to
    ``prompts`` of its prompts (the text cache off: each is new to the text encoder), each call
    after a fresh :func:`matmul_rate`; and once per round the detection stage part by part from
    outside (:func:`bench.perf.latency_measure.measure_detect_parts`). Several models (this code and
    an older copy of it) take turns call by call, the first alternating frame by frame, so that
    all see the same load."""
    from tqdm import tqdm

    names = list(models)
    enc_flops = {k: {f.sample_id: encode_flops(m, f) for f in frames} for k, m in models.items()}
    runs = {k: FloorRun(detect_parts={p: [] for p in DETECT_PARTS}) for k in names}
    old = {k: text_cache(m, 0) for k, m in models.items()}
    try:
        gr_flops: dict[str, dict[tuple[str, str], dict[str, int]]] = {}
        for k, m in models.items():
            feats = {f.sample_id: m.encode_scene(f.lidar, f.radar) for f in frames}
            gr_flops[k] = {
                (f.sample_id, p): ground_flops(m, feats[f.sample_id], p)
                for f in frames
                for p in f.prompts[:prompts]
            }
        workloads = [
            SceneWorkload(int(f.sample_id), f.lidar, f.radar, f.prompts, (), ()) for f in frames
        ]
        turn = 0
        for _ in tqdm(range(repeats), desc="floor", unit="round", disable=not progress):
            for f in frames:
                order = names if turn % 2 == 0 else names[::-1]
                turn += 1
                features = {}
                for k in order:
                    model, sid = models[k], f.sample_id
                    rate = matmul_rate()
                    # (an older copy's SceneFeatures is another class with the same fields)
                    feats, ms = _timed(lambda m=model, f=f: m.encode_scene(f.lidar, f.radar))
                    features[k] = feats
                    timings = feats.timings  # type: ignore[attr-defined]
                    stages = {s: float(getattr(timings, s)) for s in ENCODE_STAGES}
                    runs[k].calls.append(
                        TimedCall("encode", sid, rate, ms, stages, enc_flops[k][sid])
                    )
                for p in f.prompts[:prompts]:
                    for k in order:
                        model, feats = models[k], features[k]
                        rate = matmul_rate()
                        pred, ms = _timed(lambda m=model, x=feats, p=p: m.ground(x, p))
                        timings = pred.timings  # type: ignore[attr-defined]
                        stages = {s: float(getattr(timings, s)) for s in GROUND_STAGES}
                        runs[k].calls.append(
                            TimedCall(
                                "ground",
                                f.sample_id,
                                rate,
                                ms,
                                stages,
                                gr_flops[k][(f.sample_id, p)],
                            )
                        )
            for k in order:
                runs[k].detect_rates.append(matmul_rate())
                parts, _, counts = measure_detect_parts(models[k], workloads, "cpu")
                for part, v in parts.items():
                    runs[k].detect_parts[part] += v
                runs[k].candidates += counts
    finally:
        for k, m in models.items():
            text_cache(m, old[k])
    return runs
