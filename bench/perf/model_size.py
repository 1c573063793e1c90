"""Parameters and FLOPs per module of TPCNet, both presets: ``python -m bench.perf.model_size``.

FLOPs are counted by ``torch.utils.flop_counter.FlopCounterMode`` (matrix products and
convolutions, 2 FLOPs per multiply-add) over one ``model.forward`` (eval mode, batch 1) on a
synthetic scene (64-beam LiDAR, 5-scan radar) with a prompt new to the text encoder; the pillar
encoders' count depends on the number of points, the rest on the grid only. Decoding (top-K
peaks, rotated NMS) runs in numpy and has no counted FLOPs.

The text encoder (frozen MiniLM, all-MiniLM-L6-v2) is not part of the model's ``state_dict`` or
trainable parameters: it is listed separately and excluded from the trainable total; its FLOPs
are those of the benchmark prompt and grow with the prompt's length.
"""

from __future__ import annotations

import argparse
import time

import torch
from torch import nn

from bench.common import (
    BenchResult,
    FlopCount,
    SceneWorkload,
    Table,
    bench_main,
    bench_parser,
    count_flops,
    count_params,
    fmt_count,
    fmt_flops,
    machine_info,
    synthetic_scenes,
)
from model import TPCNet, build_model, load_minilm, tokenize

PROMPT = "the moving cyclists about 15 metres ahead on the left"


def module_rows(model: TPCNet) -> list[tuple[str, str, nn.Module | None]]:
    """``(label, FlopCounterMode name, module)`` of the model's parts, in data-flow order."""
    rows: list[tuple[str, str, nn.Module | None]] = []
    scene = model.scene
    for sensor in ("lidar", "radar"):
        branch = getattr(scene, sensor)
        if branch is not None:
            name = f"TPCNet.scene.{sensor}"
            rows.append((f"{sensor} pillar encoder", f"{name}.pillars", branch.pillars))
            rows.append((f"{sensor} backbone", f"{name}.backbone", branch.backbone))
    if scene.fusion is not None:
        for i, module in enumerate(scene.fusion):
            label = f"fusion stage {i + 1} ({type(module).__name__})"
            rows.append((label, f"TPCNet.scene.fusion.{i}", module))
    for i, module in enumerate(model.grounding.text_fusion):
        rows.append(
            (
                f"text fusion stage {i + 1} ({type(module).__name__})",
                f"TPCNet.grounding.text_fusion.{i}",
                module,
            )
        )
    rows.append(("neck (SECOND-FPN)", "TPCNet.scene.neck", scene.neck))
    rows.append(("head (C3D-RECHead)", "TPCNet.scene.head", scene.head))
    return rows


def measure(preset: str, scene: SceneWorkload) -> tuple[Table, dict]:
    """Parameters and FLOPs per module of the ``preset`` model on ``scene``."""
    torch.manual_seed(0)
    model = build_model(preset).eval()
    if hasattr(model.text_encoder, "cache_size"):
        model.text_encoder.cache_size = 0
    with torch.no_grad():
        flops: FlopCount = count_flops(lambda: model([scene.lidar], [scene.radar], [PROMPT]))
    rows = []
    data: dict = {"modules": {}}
    trainable = count_params(model, trainable_only=True)
    model_flops = flops.by_module.get("TPCNet", flops.total)
    text_flops = flops.by_module.get("TPCNet.text_encoder", 0)
    forward_flops = max(model_flops - text_flops, 1)
    for label, name, module in module_rows(model):
        params = count_params(module) if module is not None else 0
        f = flops.by_module.get(name, 0)
        rows.append(
            (
                label,
                fmt_count(params),
                f"{100.0 * params / max(trainable, 1):.1f} %",
                fmt_flops(f),
                f"{100.0 * f / forward_flops:.1f} %",
            )
        )
        data["modules"][label] = {"params": params, "flops": f}
    rows.append(("**TPCNet, trainable total**", f"**{fmt_count(trainable)}**", "100 %", "", ""))
    rows.append(
        (
            "**TPCNet forward, without the text encoder**",
            "",
            "",
            f"**{fmt_flops(model_flops - text_flops)}**",
            "100 %",
        )
    )
    encoder = model.text_encoder
    if model.cfg.text.encoder == "minilm":
        minilm_params = count_params(load_minilm())
        tokens = len(tokenize(PROMPT, model.cfg.text.max_tokens)[0])
        label = f"text encoder: MiniLM, frozen, not in the checkpoint ({tokens} tokens)"
    else:
        minilm_params = count_params(encoder)
        label = "text encoder: Bi-GRU (trainable, in the total above)"
    rows.append((label, fmt_count(minilm_params), "", fmt_flops(text_flops), ""))
    grid = model.cfg.pillars.grid.shape
    stages = [
        f"{c} x {grid[0] // s} x {grid[1] // s}"
        for c, s in zip(
            model.cfg.backbone.channels, model.cfg.backbone.cumulative_strides, strict=True
        )
    ]
    table = Table(
        title=f"`{preset}` preset: {grid[0]} x {grid[1]} pillars, stages (C x H x W) "
        + ", ".join(stages),
        columns=("module", "parameters", "share", "FLOPs (one forward)", "share"),
        rows=tuple(rows),
    )
    data.update(
        {
            "trainable_params": trainable,
            "forward_flops_without_text": model_flops - text_flops,
            "text_encoder_params": minilm_params,
            "text_encoder_flops": text_flops,
            "lidar_points": len(scene.lidar),
            "radar_points": len(scene.radar),
        }
    )
    return table, data


def run(quick: bool = False, command: str = "python -m bench.perf.model_size") -> BenchResult:
    """Count parameters and FLOPs for both presets (``quick`` does the same: it is one pass)."""
    start = time.perf_counter()
    machine = machine_info(command)
    scene = synthetic_scenes(1, 1, seed=0)[0]
    tables, data = [], {}
    for preset in ("small", "paper"):
        table, d = measure(preset, scene)
        tables.append(table)
        data[preset] = d
    findings = (
        f"Scene: synthetic world {scene.world_index}, {len(scene.lidar)} LiDAR and "
        f'{len(scene.radar)} radar points; prompt: "{PROMPT}".',
        "FLOPs count matrix products and convolutions (2 per multiply-add) with "
        "`torch.utils.flop_counter`; element-wise ops, softmax, pooling, the pillar scatter and "
        "the numpy decoding are not counted.",
    )
    return BenchResult(
        name="model_size",
        title="Model size: parameters and FLOPs per module",
        machine=machine,
        tables=tuple(tables),
        findings=findings,
        data=data,
        seconds=time.perf_counter() - start,
    )


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.perf.model_size``'s parser (the shared flags only)."""
    return bench_parser("bench.perf.model_size", __doc__.splitlines()[0])


def main(argv: list[str] | None = None) -> int:
    return bench_main("bench.perf.model_size", run, argv, __doc__.splitlines()[0])


if __name__ == "__main__":
    raise SystemExit(main())
