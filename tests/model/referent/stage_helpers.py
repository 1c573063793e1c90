"""Shared checks of the referent stage's explicit inputs."""

from __future__ import annotations

import numpy as np
import torch


def answers_without(model, lidar: np.ndarray, radar: np.ndarray, prompt: str, columns: slice):
    """The scores of ``prompt`` on the scene, with the stage's geometry embedding given random
    weights, and again with the weights of ``columns`` of its input zeroed: ``(before, after)``."""
    stage = model.grounding.stage
    torch.nn.init.normal_(stage.geometry[0].weight, std=1.0)
    with torch.no_grad():
        scene = model.encode_scene(lidar, radar)
        before = model.ground(scene, prompt).scores
        stage.geometry[0].weight[:, columns].zero_()
        after = model.ground(scene, prompt).scores
    return before, after
