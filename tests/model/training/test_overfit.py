"""A small TPCNet overfits a handful of synthetic samples (issue 3): the loss falls by 10x and, in
eval mode, every referred box decodes with a 3D IoU above 0.5."""

import numpy as np
import pytest
import torch

from model import build_model
from model.head.losses import grounding_loss
from model.head.targets import collate_targets, draw_targets
from scenes.datasets.grounding import GroundingDataset, collate
from scenes.geometry.boxes import iou3d
from scenes.synth.generate import SynthSettings, generate_root


@pytest.mark.slow
def test_small_model_overfits_a_handful_of_samples(tmp_path):
    torch.manual_seed(0)
    generate_root(tmp_path / "root", 6, SynthSettings(seed=11), split_fractions=(1.0, 0.0, 0.0))
    data = GroundingDataset(tmp_path / "root", "train")
    batch = collate([data[i] for i in range(3)])
    model = build_model("small")
    targets = collate_targets(
        [
            draw_targets(b, c, model.head_grid, model.cfg.head)
            for b, c in zip(batch.boxes, batch.classes, strict=True)
        ]
    )
    optimizer = torch.optim.AdamW([p for p in model.parameters() if p.requires_grad], lr=2e-3)
    losses = []
    model.train()
    for _ in range(120):
        out = model(list(batch.lidar), list(batch.radar), list(batch.prompts))
        loss = grounding_loss(out, targets).total
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert np.mean(losses[-5:]) < np.mean(losses[:5]) / 10

    # Re-estimate BatchNorm statistics on these scenes, then answer in eval mode.
    for module in model.modules():
        if isinstance(module, torch.nn.modules.batchnorm._BatchNorm):
            module.reset_running_stats()
            module.momentum = None  # cumulative average
    with torch.no_grad():
        for _ in range(3):
            model(list(batch.lidar), list(batch.radar), list(batch.prompts))
    model.eval()
    for lidar, radar, prompt, boxes in zip(
        batch.lidar, batch.radar, batch.prompts, batch.boxes, strict=True
    ):
        pred = model.ground(model.encode_scene(lidar, radar), prompt, score_threshold=0.3)
        assert len(pred.boxes) > 0, prompt
        best = iou3d(boxes, pred.boxes).max(axis=1)
        assert np.all(best > 0.5), (prompt, best)
