"""A 64-beam spinning LiDAR (HDL-64-like) ray-cast against a :class:`~scenes.world.World`.

Sensor
    At the LiDAR origin (the world's ground is ``lidar_height`` below it). 64 beams: an upper block
    of 32 from +2.0 to -8.33 degrees and a lower block of 32 from -8.83 to -24.8 degrees, as the
    HDL-64's two laser blocks. The spin is sampled every ``azimuth_step_deg`` (0.17 degrees: an
    HDL-64 at 10 Hz), but only over the forward sector ``|azimuth| <= azimuth_half_fov_deg``, which
    holds the annotated area (x in [0, 51.2] m) and the camera's view (+-32 degrees): the rest of
    the spin would be cropped away anyway. Points come from one spin at ``t = 0`` (no motion skew).

Return model
    A return of a surface of reflectivity ``rho`` at range ``r`` and incidence ``theta`` carries a
    power proportional to ``rho * sqrt(cos theta) * exp(-2 * extinction * r) / r**2`` (the square
    root softens Lambert's law, which real grazing returns from roads do not follow strictly). It is
    detected when this, jittered by log-normal speckle, exceeds the power of a 10 % target at normal
    incidence at ``reference_range`` in clear air. Then: random dropout (sensor, weather and
    material), Gaussian range noise (2 cm), material depth jitter (foliage), the maximum range, and
    weather backscatter (a spurious weak return a few metres out, replacing the true one).

Intensity
    ``255 * rho * (0.3 + 0.7 cos theta) * exp(-2 * extinction * r)`` with 3 % noise, clipped to
    ``[0, 255]``: a reflectivity-like value, like the calibrated intensities of the HDL-64.

The output ``(N, 4)`` float32 ``x, y, z, intensity`` is in the LiDAR frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache

import numpy as np

from scenes.weather import CLEAR, Weather
from scenes.world import LIDAR_DEPTH_JITTER, LIDAR_DROPOUT, REFLECTIVITY, RayCaster

BACKSCATTER = -2
"""``owner`` of a point produced by weather backscatter (actors are >= 0, static geometry -1)."""


@dataclass(frozen=True)
class LidarConfig:
    """The LiDAR's layout and noise.

    Attributes:
        upper_block: ``(top, bottom)`` elevation (deg) of the upper 32 beams.
        lower_block: ``(top, bottom)`` elevation (deg) of the lower 32 beams.
        beams_per_block: 32 (64 beams in all).
        azimuth_step_deg: Horizontal sampling step.
        azimuth_half_fov_deg: Cast only ``|azimuth| <=`` this (forward sector).
        min_range, max_range: Returns outside are discarded (m).
        range_noise: Standard deviation of the range noise (m).
        dropout: Base probability that a return is lost.
        reference_range: Range (m) at which a 10 %-reflective target at normal incidence is at the
            detection threshold in clear air.
        speckle: Standard deviation of the log-normal jitter of the return power.
        intensity_noise: Relative standard deviation of the intensity.
    """

    upper_block: tuple[float, float] = (2.0, -8.33)
    lower_block: tuple[float, float] = (-8.83, -24.8)
    beams_per_block: int = 32
    azimuth_step_deg: float = 0.17
    azimuth_half_fov_deg: float = 45.0
    min_range: float = 1.0
    max_range: float = 120.0
    range_noise: float = 0.02
    dropout: float = 0.01
    reference_range: float = 100.0
    speckle: float = 0.25
    intensity_noise: float = 0.03


@dataclass(frozen=True)
class LidarScan:
    """One simulated sweep.

    Attributes:
        points: ``(N, 4)`` float32 ``x, y, z, intensity`` (0..255), LiDAR frame.
        owner: ``(N,)`` int: actor index, -1 for static geometry, :data:`BACKSCATTER` for weather.
    """

    points: np.ndarray = field(repr=False)
    owner: np.ndarray = field(repr=False)


def beam_elevations(config: LidarConfig = LidarConfig()) -> np.ndarray:
    """``(64,)`` beam elevations in degrees, top to bottom."""
    n = config.beams_per_block
    return np.concatenate(
        [np.linspace(*config.upper_block, n), np.linspace(*config.lower_block, n)]
    )


@cache
def ray_directions(config: LidarConfig = LidarConfig()) -> np.ndarray:
    """``(R, 3)`` unit ray directions (beam-major), LiDAR frame."""
    half = config.azimuth_half_fov_deg
    azimuth = np.deg2rad(np.arange(-half, half + 1e-9, config.azimuth_step_deg))
    elevation = np.deg2rad(beam_elevations(config))
    el, az = np.meshgrid(elevation, azimuth, indexing="ij")
    dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)
    dirs = dirs.reshape(-1, 3)
    dirs.setflags(write=False)
    return dirs


def simulate_lidar(
    caster: RayCaster,
    rng: np.random.Generator,
    config: LidarConfig = LidarConfig(),
    weather: Weather = CLEAR,
) -> LidarScan:
    """One LiDAR sweep of ``caster.world`` at ``t = 0`` (see the module docstring)."""
    dirs = ray_directions(config)
    r_count = len(dirs)
    hits = caster.cast(np.zeros((r_count, 3)), dirs, time=0.0)
    # Random draws for every ray, in a fixed order, so the stream does not depend on the hits.
    speckle = rng.lognormal(0.0, config.speckle, r_count)
    drop_draw = rng.random(r_count)
    range_noise = rng.normal(0.0, config.range_noise * weather.lidar_noise_scale, r_count)
    depth_draw = rng.random(r_count)
    intensity_noise = rng.normal(0.0, config.intensity_noise, r_count)
    scatter_draw = rng.random(r_count)
    scatter_range = config.min_range + rng.exponential(weather.backscatter_range, r_count)
    scatter_intensity = rng.uniform(0.0, 12.0, r_count)

    hit = hits.hit
    mat = np.where(hit, hits.material, 0)
    rho = REFLECTIVITY[mat]
    dist = np.where(hit, hits.distance, np.inf)
    cos_inc = hits.cos_incidence
    transmission = np.exp(-2.0 * weather.lidar_extinction * np.where(hit, dist, 0.0))
    with np.errstate(divide="ignore"):
        power = rho * np.sqrt(cos_inc) * transmission / np.maximum(dist, 1e-3) ** 2
    threshold = 0.1 / config.reference_range**2
    keep = hit & (power * speckle >= threshold)
    keep &= drop_draw >= config.dropout + weather.lidar_dropout + LIDAR_DROPOUT[mat]
    measured = dist + range_noise + LIDAR_DEPTH_JITTER[mat] * depth_draw
    keep &= (measured >= config.min_range) & (measured <= config.max_range)
    intensity = 255.0 * rho * (0.3 + 0.7 * cos_inc) * transmission * (1.0 + intensity_noise)
    owner = np.where(hit, hits.owner, -1)

    scatter = (scatter_draw < weather.backscatter_prob) & (
        scatter_range < np.where(keep, measured, np.inf)
    )
    measured = np.where(scatter, scatter_range, measured)
    intensity = np.where(scatter, scatter_intensity, intensity)
    owner = np.where(scatter, BACKSCATTER, owner)
    keep |= scatter

    points = np.empty((int(keep.sum()), 4), dtype=np.float32)
    points[:, :3] = dirs[keep] * measured[keep, None]
    points[:, 3] = np.clip(intensity[keep], 0.0, 255.0)
    return LidarScan(points=points, owner=owner[keep].astype(np.int64))
