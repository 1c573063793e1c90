"""Weather as it affects the two sensors: fog and rain degrade the LiDAR, barely the radar.

LiDAR (905 nm): the return power of a diffuse target falls as ``exp(-2 * extinction * range)``
on top of the ``1 / range**2`` law, so the extinction coefficient sets how far the sensor still
sees; droplets also scatter light straight back, producing spurious returns a few metres from the
sensor. Dense fog (visibility about 25 m, extinction 0.12 /m) removes nearly every return beyond
15-20 m; rain (0.01 /m) costs a little range, some returns and adds noise.

Radar (77 GHz): attenuation by fog is negligible and by rain small, so the only effects are a
slightly higher noise floor (detection loss in dB) and noisier measurements. This contrast is the
TPCNet paper's reason for fusing the two sensors.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Weather:
    """Sensor degradation parameters.

    Attributes:
        name: ``clear``, ``rain`` or ``fog`` (recorded in the sample sidecar).
        lidar_extinction: Atmospheric extinction coefficient at 905 nm (1/m, one way).
        lidar_dropout: Extra probability that a return is lost.
        lidar_noise_scale: Multiplies the LiDAR range noise.
        backscatter_prob: Probability per ray of a spurious return from the droplets.
        backscatter_range: Mean range (m, exponential beyond 1 m) of those spurious returns.
        radar_loss_db: Loss of radar signal-to-noise ratio (dB).
        radar_noise_scale: Multiplies the radar position and velocity noise.
    """

    name: str
    lidar_extinction: float = 0.0
    lidar_dropout: float = 0.0
    lidar_noise_scale: float = 1.0
    backscatter_prob: float = 0.0
    backscatter_range: float = 3.0
    radar_loss_db: float = 0.0
    radar_noise_scale: float = 1.0


CLEAR = Weather("clear")
RAIN = Weather(
    "rain",
    lidar_extinction=0.01,
    lidar_dropout=0.06,
    lidar_noise_scale=2.0,
    backscatter_prob=0.004,
    backscatter_range=6.0,
    radar_loss_db=1.0,
    radar_noise_scale=1.2,
)
FOG = Weather(
    "fog",
    lidar_extinction=0.12,
    lidar_dropout=0.02,
    lidar_noise_scale=1.5,
    backscatter_prob=0.05,
    backscatter_range=3.0,
    radar_loss_db=0.3,
    radar_noise_scale=1.1,
)

WEATHERS: dict[str, Weather] = {w.name: w for w in (CLEAR, RAIN, FOG)}
"""The weathers by name, for command lines."""


def weather_named(name: str) -> Weather:
    """The :class:`Weather` called ``name``; a ValueError lists the known names otherwise."""
    try:
        return WEATHERS[name]
    except KeyError:
        raise ValueError(f"unknown weather {name!r}: expected one of {sorted(WEATHERS)}") from None
