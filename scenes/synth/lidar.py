"""A 64-beam spinning LiDAR (HDL-64-like) ray-cast against a :class:`~scenes.synth.world.World`.

Sensor
    At the LiDAR origin (the world's ground is ``lidar_height`` below it). 64 beams: an upper block
    of 32 from +2.0 to -8.33 degrees (1/3 degree apart) and a lower block of 32 from -8.87 to -24.9
    degrees (about 1/2 degree apart), as the HDL-64's two laser blocks (vertical field of view +2 to
    -24.9 degrees). The spin is sampled every ``azimuth_step_deg`` (0.08 degrees, about 290,000
    rays per revolution: about 41,000 returns in the camera's field of view, within 20 % of
    View-of-Delft's ~34,300, and the per-object counts of ``docs/SENSOR_STATS.md``), but only over
    the forward half ``|azimuth| <= azimuth_half_fov_deg`` (90 degrees): everything a model's grid
    can hold (``x >= 0``, up to +-90 degrees beside the ego at short range), as a real 360-degree
    scan has it; the rear half would be cropped away anyway. Points come from one spin at ``t = 0``
    (no motion skew).

Return model
    A return of a surface of reflectivity ``rho`` at range ``r`` and incidence ``theta`` carries a
    power proportional to ``rho * sqrt(cos theta) * exp(-2 * extinction * r) / r**2`` (the square
    root softens Lambert's law, which real grazing returns from roads do not follow strictly). It is
    detected when this, jittered by log-normal speckle, exceeds the power of a 10 % target at normal
    incidence at ``reference_range`` in clear air (50 m: the HDL-64 data sheet's range for a 10 %
    target; dark clothes, about 12 %, thin out beyond 30 m as in View-of-Delft's scans). Then:
    random dropout (sensor, weather and material), Gaussian range noise (2 cm), material depth
    jitter (foliage), the maximum range, and weather backscatter (a spurious weak return a few
    metres out, replacing the true one).

Intensity
    ``255 * min(1, gain * (rho * (floor + (1 - floor) cos theta))**gamma) * exp(-2 * extinction *
    r)`` with log-normal noise (``intensity_noise``), clipped to ``[0, 255]``: a compressive,
    reflectivity-like value as the calibrated intensities of View-of-Delft's HDL-64, whose
    field-of-view points have p10 / p50 / p90 of about 40 / 108 / 215 (issue 14).

Other rigs (:mod:`scenes.synth.setups`, :mod:`scenes.synth.randomise`)
    The beams' count and pattern, the azimuth step, a pitch of the mount (``pitch_deg``: rays cast
    turned, points reported in the pitched sensor's frame), an intensity scale and dead beams
    are :class:`LidarConfig` fields; their defaults leave the sweep (and its random stream) as
    described above.

The output ``(N, 4)`` float32 ``x, y, z, intensity`` is in the LiDAR frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache

import numpy as np

from scenes.synth.weather import CLEAR, Weather
from scenes.synth.world import LIDAR_DEPTH_JITTER, LIDAR_DROPOUT, REFLECTIVITY, RayCaster

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
        intensity_floor: Share of the intensity that does not depend on the incidence.
        intensity_gamma: Exponent of the intensity response (``< 1``: compressive, as the
            HDL-64's calibrated intensities, which spread dark surfaces over much of 0..255).
        intensity_gain: Scale before clipping to 255 (bright targets saturate).
        intensity_noise: Standard deviation of the log-normal jitter of the intensity.
        pitch_deg: The sensor's pitch on its mount, nose down positive (degrees): the rays are
            cast turned by it about the y axis, and the points are reported in the sensor's own
            (pitched) frame, as an uncorrected mounting would give them; 0: level.
        intensity_scale: Factor on the intensity before clipping to 255 (another sensor's
            intensity calibration; 1: as modelled above).
        beam_dropout: Share of beams dead for the whole sweep (each beam drawn independently;
            drawn after every other draw, so 0 leaves the random stream as it was).
    """

    upper_block: tuple[float, float] = (2.0, -8.33)
    lower_block: tuple[float, float] = (-8.87, -24.9)
    beams_per_block: int = 32
    azimuth_step_deg: float = 0.08
    azimuth_half_fov_deg: float = 90.0
    min_range: float = 1.0
    max_range: float = 120.0
    range_noise: float = 0.02
    dropout: float = 0.01
    reference_range: float = 50.0
    incidence_exponent: float = 1.0
    speckle: float = 0.25
    intensity_floor: float = 0.2
    intensity_gamma: float = 0.6
    intensity_gain: float = 1.3
    intensity_noise: float = 0.55
    pitch_deg: float = 0.0
    intensity_scale: float = 1.0
    beam_dropout: float = 0.0

    @property
    def beams(self) -> int:
        """Beams in all (two blocks)."""
        return 2 * self.beams_per_block


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
    """``(config.beams,)`` beam elevations in degrees (sensor frame), top to bottom."""
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


def intensity_response(rho: np.ndarray, cos_inc: np.ndarray, config: LidarConfig) -> np.ndarray:
    """Noise-free intensity in ``[0, 1]`` (times 255 on the sensor's scale) of surfaces of
    reflectivity ``rho (R,)`` hit at incidence ``cos_inc (R,)``, in clear air."""
    floor = config.intensity_floor
    shaded = np.asarray(rho) * (floor + (1.0 - floor) * np.asarray(cos_inc))
    return np.minimum(1.0, config.intensity_gain * shaded**config.intensity_gamma)


def pitch_rotation(pitch_deg: float) -> np.ndarray:
    """``(3, 3)`` sensor -> level frame of a sensor pitched ``pitch_deg`` nose down (about +y)."""
    c, s = np.cos(np.deg2rad(pitch_deg)), np.sin(np.deg2rad(pitch_deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def simulate_lidar(
    caster: RayCaster,
    rng: np.random.Generator,
    config: LidarConfig = LidarConfig(),
    weather: Weather = CLEAR,
) -> LidarScan:
    """One LiDAR sweep of ``caster.world`` at ``t = 0`` (see the module docstring)."""
    dirs = ray_directions(config)  # the sensor's frame
    r_count = len(dirs)
    cast = dirs if config.pitch_deg == 0.0 else dirs @ pitch_rotation(config.pitch_deg).T
    hits = caster.cast(np.zeros((r_count, 3)), cast, time=0.0)
    # Random draws for every ray, in a fixed order, so the stream does not depend on the hits.
    speckle = rng.lognormal(0.0, config.speckle, r_count)
    drop_draw = rng.random(r_count)
    range_noise = rng.normal(0.0, config.range_noise * weather.lidar_noise_scale, r_count)
    depth_draw = rng.random(r_count)
    intensity_noise = rng.lognormal(0.0, config.intensity_noise, r_count)
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
        power = (
            rho * cos_inc**config.incidence_exponent * transmission / np.maximum(dist, 1e-3) ** 2
        )
    threshold = 0.1 / config.reference_range**2
    keep = hit & (power * speckle >= threshold)
    keep &= drop_draw >= config.dropout + weather.lidar_dropout + LIDAR_DROPOUT[mat]
    measured = dist + range_noise + LIDAR_DEPTH_JITTER[mat] * depth_draw
    keep &= (measured >= config.min_range) & (measured <= config.max_range)
    intensity = 255.0 * intensity_response(rho, cos_inc, config) * transmission * intensity_noise
    if config.intensity_scale != 1.0:
        intensity = intensity * config.intensity_scale
    owner = np.where(hit, hits.owner, -1)

    scatter = (scatter_draw < weather.backscatter_prob) & (
        scatter_range < np.where(keep, measured, np.inf)
    )
    measured = np.where(scatter, scatter_range, measured)
    intensity = np.where(scatter, scatter_intensity, intensity)
    owner = np.where(scatter, BACKSCATTER, owner)
    keep |= scatter
    if config.beam_dropout > 0.0:  # whole beams dead (rays are beam-major)
        dead = rng.random(config.beams) < config.beam_dropout
        keep &= ~np.repeat(dead, r_count // config.beams)

    points = np.empty((int(keep.sum()), 4), dtype=np.float32)
    points[:, :3] = dirs[keep] * measured[keep, None]
    points[:, 3] = np.clip(intensity[keep], 0.0, 255.0)
    return LidarScan(points=points, owner=owner[keep].astype(np.int64))
