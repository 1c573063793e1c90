"""A prompt's numbers compared with each candidate's measured depth and speed, explicitly.

"cyclists faster than 50 km/h" names no cyclist of a scene whose cyclists ride at 20: the stage
must compare the prompt's number, in its unit, with each candidate's speed. The numbers reach the
stage as token features (:mod:`model.nets.numerals`) and the speeds as radar evidence
(:func:`model.referent.candidates.radar_evidence`), in different tokens; attention learned the
prompts' speed words from that but not the comparison (measured: with stage 3d "cyclists faster
than 50 km/h" boxed as many cyclists as "cyclists" on validation scenes). So, as for ranks
(:mod:`model.referent.context`), the comparison is stated: for each of the prompt's first
:data:`COMPARE_NUMBERS` numbers ``v`` (a run of tokens of one value) and each candidate,

- depth: ``sigmoid((d - v) / DEPTH_TAU)`` and ``exp(-(d - v)^2 / (2 DEPTH_TAU^2))``, ``d`` the
  nearest-edge depth in metres ("beyond 40 m", "about 20 m");
- speed, with ``v`` read in each unit of :data:`SPEED_UNITS` (m/s, km/h, mph):
  ``sigmoid((s - v u) / SPEED_TAU)`` and the bump, ``s`` the larger of the radar's median
  ego-compensated radial speed and its points' displacement rate (crossing motion);
- whether the number exists.

Which of these a sentence means (a distance or a speed, which unit, above or below) is left to the
stage: its text gate and layers read the words around the number. The numbers are bounded where
they are read (:mod:`model.nets.numerals`: a distance beyond the sensors' range reads as "beyond
range", a count beyond the candidates as the candidates) and again here, so no comparison is NaN. Pure torch functions of the
stage's inputs, for all candidates and prompts at once; no text parsing beyond the numerals'.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

from model.nets.numerals import MAX_NUMBER
from model.referent.candidates import (
    DEPTH_COLUMN,
    DEPTH_SCALE,
    RADAR_EVIDENCE,
    RADAR_MEDIAN_VC,
    RADAR_SLOPE_X,
    RADAR_SLOPE_Y,
    SPEED_SCALE,
)

COMPARE_NUMBERS = 2
SPEED_UNITS = (1.0, 1.0 / 3.6, 0.44704)
"""Metres per second of one unit of each reading of a speed: m/s, km/h, mph."""
DEPTH_TAU = 2.0
SPEED_TAU = 0.7
PER_NUMBER = 2 + 2 * len(SPEED_UNITS) + 1
COMPARE_FEATURES = COMPARE_NUMBERS * PER_NUMBER


def prompt_numbers(numbers: Tensor, padding: Tensor) -> tuple[Tensor, Tensor]:
    """The values of a prompt's first :data:`COMPARE_NUMBERS` numbers.

    Args:
        numbers: ``(N, T, NUMERIC_FEATURES)`` token numeric features (flag, value / 10, ...).
        padding: ``(N, T)`` bool, True at padding.

    Returns:
        ``values`` ``(N, COMPARE_NUMBERS)`` in ``[0, MAX_NUMBER]`` (0 where absent; a value
        that is not finite or is larger reads as :data:`model.nets.numerals.MAX_NUMBER`) and
        ``present`` ``(N, COMPARE_NUMBERS)`` float (1 where the prompt has that many numbers). A number is a run
        of number tokens of one value ("twenty five" is two tokens of 25).
    """
    flag = (numbers[..., 0] > 0.5) & ~padding
    # Bounded again where read back (the numerals bound what they write: MAX_NUMBER): features
    # made elsewhere (a cache, a caller) can never make a comparison NaN or infinite.
    value = torch.nan_to_num(numbers[..., 1] * 10.0, nan=MAX_NUMBER, posinf=MAX_NUMBER)
    value = value.clamp(0.0, MAX_NUMBER)
    prev_flag = F.pad(flag[:, :-1], (1, 0), value=False)
    prev_value = F.pad(value[:, :-1], (1, 0))
    start = flag & ~(prev_flag & (value == prev_value))
    ordinal = torch.cumsum(start.to(torch.int64), dim=1)
    values, present = [], []
    for j in range(COMPARE_NUMBERS):
        hit = (start & (ordinal == j + 1)).to(value.dtype)
        values.append((value * hit).sum(1))
        present.append(hit.sum(1).clamp(max=1.0))
    return torch.stack(values, 1), torch.stack(present, 1)


def candidate_speed(radar: Tensor | None, like: Tensor) -> Tensor:
    """Each candidate's speed estimate ``(N, K)`` in m/s from the radar tensor ``(N, K, C_r +
    RADAR_EVIDENCE)`` (zero without radar: a LiDAR-only model)."""
    if radar is None:
        return like.new_zeros(like.shape[:2])
    ev = radar[..., radar.shape[-1] - RADAR_EVIDENCE :]
    doppler = ev[..., RADAR_MEDIAN_VC].abs() * SPEED_SCALE
    displacement = torch.hypot(ev[..., RADAR_SLOPE_X], ev[..., RADAR_SLOPE_Y])
    return torch.maximum(doppler, displacement)


def compare_features(
    geometry: Tensor, radar: Tensor | None, numbers: Tensor, padding: Tensor
) -> Tensor:
    """The comparisons of the module docstring, ``(N, K, COMPARE_FEATURES)``.

    Args:
        geometry: ``(N, K, >= GEOMETRY_FEATURES)`` candidate geometry (its depth column is read).
        radar: ``(N, K, C_r + RADAR_EVIDENCE)`` or None.
        numbers: ``(N, T, NUMERIC_FEATURES)``; padding: ``(N, T)`` text padding.
    """
    if not bool((numbers[..., 0] > 0.5).any()):  # no number in any prompt: every column is 0
        return geometry.new_zeros((*geometry.shape[:2], COMPARE_FEATURES))
    values, present = prompt_numbers(numbers.to(geometry.dtype), padding)
    v, on = values[:, None, :], present[:, None, :]  # (N, 1, M)
    depth = geometry[..., DEPTH_COLUMN, None] * DEPTH_SCALE  # (N, K, 1)
    speed = candidate_speed(radar, geometry)[..., None]
    cols = [
        torch.sigmoid((depth - v) / DEPTH_TAU),
        torch.exp(-0.5 * ((depth - v) / DEPTH_TAU) ** 2),
    ]
    for unit in SPEED_UNITS:
        gap = (speed - v * unit) / SPEED_TAU
        cols += [torch.sigmoid(gap), torch.exp(-0.5 * gap**2)]
    per = torch.stack([c * on for c in cols] + [on.expand_as(cols[0])], dim=-1)  # (N, K, M, P)
    return per.flatten(2)


__all__ = ["COMPARE_FEATURES", "candidate_speed", "compare_features", "prompt_numbers"]
