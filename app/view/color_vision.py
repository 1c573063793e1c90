"""How far apart two colours look: CIELAB, the CIEDE2000 colour difference and simulated
colour-vision deficiency (pure numpy, no colour library).

The app's colours that a person must tell apart (the class colours of :mod:`app.view.colors`, the
referent's colour) are checked with these: :func:`delta_e2000` between every pair, seen with
normal vision and as a person with deuteranopia or protanopia sees them (:func:`simulate`,
Machado, Oliveira and Fernandes 2009, severity 1.0: a 3 x 3 matrix on linear sRGB).

- sRGB (8 bit, D65) -> linear RGB -> CIE XYZ -> CIELAB (:func:`srgb_to_lab`), the standard
  formulas (IEC 61966-2-1, CIE 15);
- CIEDE2000 (:func:`delta_e2000`): Sharma, Wu and Dalal 2005's statement of the formula, with
  ``kL = kC = kH = 1``; about 1 is a just noticeable difference, and colours a reader tells apart
  at a glance in a legend are some 20 or more apart.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "MACHADO",
    "delta_e2000",
    "linear_to_srgb",
    "min_pair_distance",
    "simulate",
    "srgb_to_lab",
    "srgb_to_linear",
]

MACHADO: dict[str, np.ndarray] = {
    "deuteranopia": np.array(
        [
            [0.367322, 0.860646, -0.227968],
            [0.280085, 0.672501, 0.047413],
            [-0.011820, 0.042940, 0.968881],
        ]
    ),
    "protanopia": np.array(
        [
            [0.152286, 1.052583, -0.204868],
            [0.114503, 0.786281, 0.099216],
            [-0.003882, -0.048116, 1.051998],
        ]
    ),
}
"""Machado et al. 2009's matrices for dichromacy (severity 1.0), applied to linear sRGB."""

_SRGB_TO_XYZ = np.array(
    [
        [0.4124564, 0.3575761, 0.1804375],
        [0.2126729, 0.7151522, 0.0721750],
        [0.0193339, 0.1191920, 0.9503041],
    ]
)
_WHITE_D65 = np.array([0.95047, 1.0, 1.08883])


def srgb_to_linear(rgb: np.ndarray | Sequence) -> np.ndarray:
    """8-bit sRGB ``(..., 3)`` -> linear RGB in ``[0, 1]``."""
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    """Linear RGB ``(..., 3)`` (clipped to ``[0, 1]``) -> sRGB in ``[0, 255]`` (float)."""
    c = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return 255.0 * np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def simulate(rgb: np.ndarray | Sequence, deficiency: str) -> np.ndarray:
    """How ``rgb`` (8-bit sRGB ``(..., 3)``) looks with ``deficiency`` (a key of
    :data:`MACHADO`; ``"normal"``: unchanged), as 8-bit sRGB (float)."""
    if deficiency == "normal":
        return np.asarray(rgb, dtype=np.float64)
    matrix = MACHADO[deficiency]
    return linear_to_srgb(srgb_to_linear(rgb) @ matrix.T)


def srgb_to_lab(rgb: np.ndarray | Sequence) -> np.ndarray:
    """8-bit sRGB ``(..., 3)`` -> CIELAB ``(..., 3)`` (D65 white)."""
    xyz = srgb_to_linear(rgb) @ _SRGB_TO_XYZ.T / _WHITE_D65
    eps, kappa = 216 / 24389, 24389 / 27
    f = np.where(xyz > eps, np.cbrt(xyz), (kappa * xyz + 16) / 116)
    return np.stack(
        [116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])],
        axis=-1,
    )


def delta_e2000(lab1: np.ndarray | Sequence, lab2: np.ndarray | Sequence) -> np.ndarray:
    """The CIEDE2000 difference of CIELAB colours ``(..., 3)`` (broadcast; ``kL = kC = kH = 1``)."""
    l1, a1, b1 = np.moveaxis(np.asarray(lab1, dtype=np.float64), -1, 0)
    l2, a2, b2 = np.moveaxis(np.asarray(lab2, dtype=np.float64), -1, 0)
    c_mean = (np.hypot(a1, b1) + np.hypot(a2, b2)) / 2
    g = 0.5 * (1 - np.sqrt(c_mean**7 / (c_mean**7 + 25.0**7)))
    a1p, a2p = (1 + g) * a1, (1 + g) * a2
    c1p, c2p = np.hypot(a1p, b1), np.hypot(a2p, b2)
    h1p = np.degrees(np.arctan2(b1, a1p)) % 360
    h2p = np.degrees(np.arctan2(b2, a2p)) % 360
    dl, dc = l2 - l1, c2p - c1p
    dh = h2p - h1p
    dh = np.where(dh > 180, dh - 360, np.where(dh < -180, dh + 360, dh))
    dh = np.where(c1p * c2p == 0, 0.0, dh)
    dhh = 2 * np.sqrt(c1p * c2p) * np.sin(np.radians(dh / 2))
    l_mean, cp_mean = (l1 + l2) / 2, (c1p + c2p) / 2
    h_sum = h1p + h2p
    h_mean = np.where(
        np.abs(h1p - h2p) <= 180, h_sum / 2, np.where(h_sum < 360, h_sum / 2 + 180, h_sum / 2 - 180)
    )
    h_mean = np.where(c1p * c2p == 0, h_sum, h_mean)
    t = (
        1
        - 0.17 * np.cos(np.radians(h_mean - 30))
        + 0.24 * np.cos(np.radians(2 * h_mean))
        + 0.32 * np.cos(np.radians(3 * h_mean + 6))
        - 0.20 * np.cos(np.radians(4 * h_mean - 63))
    )
    sl = 1 + 0.015 * (l_mean - 50) ** 2 / np.sqrt(20 + (l_mean - 50) ** 2)
    sc = 1 + 0.045 * cp_mean
    sh = 1 + 0.015 * cp_mean * t
    rt = (
        -2
        * np.sqrt(cp_mean**7 / (cp_mean**7 + 25.0**7))
        * np.sin(np.radians(60 * np.exp(-(((h_mean - 275) / 25) ** 2))))
    )
    return np.sqrt((dl / sl) ** 2 + (dc / sc) ** 2 + (dhh / sh) ** 2 + rt * (dc / sc) * (dhh / sh))


def min_pair_distance(
    colors: dict[str, tuple[int, int, int]], deficiency: str = "normal"
) -> tuple[float, tuple[str, str]]:
    """The smallest CIEDE2000 difference between two of ``colors`` (name -> 8-bit sRGB) as seen
    with ``deficiency`` (:func:`simulate`), and the pair of names it is between."""
    names = list(colors)
    if len(names) < 2:
        raise ValueError("min_pair_distance: need two colours or more")
    lab = srgb_to_lab(simulate(np.array([colors[n] for n in names]), deficiency))
    d = delta_e2000(lab[:, None], lab[None, :])
    d[np.diag_indices(len(names))] = np.inf
    i, j = np.unravel_index(int(np.argmin(d)), d.shape)
    return float(d[i, j]), (names[min(i, j)], names[max(i, j)])
