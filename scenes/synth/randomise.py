"""Sensor randomisation for training (``python -m scenes.synth --sensor-randomise``; issue 38,
item 2): every world is sensed through a rig drawn from :class:`SensorRandomisation`'s ranges, so
that a detector trained on the root does not learn one sensor.

Per world, from its own stream (:func:`sensor_stream`: ``SeedSequence([seed, world]).spawn(7)[6]``,
beside the six of :func:`scenes.synth.frame.world_streams`, which stay as they were), so the
world, its actors and its prompts are those of the same seed without randomisation:

* LiDAR beams: a count from :attr:`SensorRandomisation.beams` and a pattern (top, the split
  between the two blocks, bottom) from the elevation ranges; azimuth step, height, pitch,
  per-return dropout, dead beams, intensity scale (log-uniform) and range noise from theirs.
* radar: scans (newest first, at most the root's ``--radar-scans``), static-surface density,
  clutter, and a factor on the position and velocity noise.

What the ranges exclude (the held-out set-ups of :mod:`scenes.synth.setups`, values not drawn):
beam counts 32 and 128 (:attr:`beams` holds neither); nuScenes' +10.67 / -30.67 degree span and
the 128-beam +15 degree top (tops are at most 4 degrees, bottoms at least -28); nuScenes' 0.33
degree azimuth step (steps at most 0.2); heights 1.40 and 1.84 m (drawn in [1.5, 1.8]); a 2 degree
pitch (drawn in [-1.5, 1.5]); intensity x0.5 and x2 (drawn in [0.6, 1.6]); a single radar scan
(at least 2); the ARS-408's sparse static returns (a 0.05 density; drawn at least 0.3) and its
handful of clutter points (drawn at least 10 a scan). Streets are not randomised (their densities
are held out whole).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from scenes.synth.lidar import LidarConfig
from scenes.synth.radar import RadarConfig
from scenes.synth.setups import SensorSetup

SENSOR_STREAM = 6
"""Index of the sensor rig's stream among a world's spawned seed sequences."""


@dataclass(frozen=True)
class SensorRandomisation:
    """The ranges a world's rig is drawn from (module docstring); ``(low, high)`` are uniform.

    Attributes:
        beams: LiDAR beam counts to choose from (even; two blocks of half each).
        top_deg, split_deg, bottom_deg: Elevation of the top beam, of the split between the two
            blocks, of the bottom beam.
        azimuth_step_deg: Horizontal sampling step.
        height: LiDAR above the ground (m).
        pitch_deg: Pitch, nose down positive.
        dropout: Per-return loss probability.
        beam_dropout: Share of dead beams.
        intensity_scale: Log-uniform factor on the intensity.
        range_noise: Range noise standard deviation (m).
        radar_scans: Smallest and largest scan count (capped by the root's).
        static_prob_scale: Radar static-surface detection factor.
        clutter_per_scan: Radar clutter points per scan.
        radar_noise: Factor on the radar's range, angle and velocity noise.
    """

    beams: tuple[int, ...] = (40, 48, 56, 64, 72, 80, 96)
    top_deg: tuple[float, float] = (0.0, 4.0)
    split_deg: tuple[float, float] = (-10.0, -6.0)
    bottom_deg: tuple[float, float] = (-28.0, -20.0)
    azimuth_step_deg: tuple[float, float] = (0.07, 0.2)
    height: tuple[float, float] = (1.5, 1.8)
    pitch_deg: tuple[float, float] = (-1.5, 1.5)
    dropout: tuple[float, float] = (0.0, 0.08)
    beam_dropout: tuple[float, float] = (0.0, 0.1)
    intensity_scale: tuple[float, float] = (0.6, 1.6)
    range_noise: tuple[float, float] = (0.01, 0.05)
    radar_scans: tuple[int, int] = (2, 5)
    static_prob_scale: tuple[float, float] = (0.3, 1.5)
    clutter_per_scan: tuple[float, float] = (10.0, 80.0)
    radar_noise: tuple[float, float] = (0.5, 2.0)

    def draw(
        self,
        rng: np.random.Generator,
        max_scans: int,
        lidar: LidarConfig | None = None,
        radar: RadarConfig | None = None,
    ) -> SensorSetup:
        """One rig: ``lidar`` and ``radar`` (default: the simulators' defaults) with the drawn
        values (a fixed number of draws in a fixed order, whatever their values)."""
        lidar = LidarConfig() if lidar is None else lidar
        radar = RadarConfig() if radar is None else radar
        if max_scans < self.radar_scans[0]:
            raise ValueError(
                f"sensor randomisation draws {self.radar_scans[0]} to {self.radar_scans[1]} "
                f"radar scans; a root of {max_scans} scan(s) cannot hold them (--radar-scans 3 or 5)"
            )
        u = rng.uniform
        beams = int(self.beams[int(rng.integers(len(self.beams)))])
        top, split, bottom = u(*self.top_deg), u(*self.split_deg), u(*self.bottom_deg)
        half = beams // 2
        gap = (top - split) / half  # the lower block starts one upper-block spacing below
        lid = replace(
            lidar,
            beams_per_block=half,
            upper_block=(float(top), float(split)),
            lower_block=(float(split - gap), float(bottom)),
            azimuth_step_deg=float(u(*self.azimuth_step_deg)),
            pitch_deg=float(u(*self.pitch_deg)),
            dropout=float(u(*self.dropout)),
            beam_dropout=float(u(*self.beam_dropout)),
            intensity_scale=float(np.exp(u(*np.log(self.intensity_scale)))),
            range_noise=float(u(*self.range_noise)),
        )
        height = float(u(*self.height))
        scans = int(rng.integers(self.radar_scans[0], self.radar_scans[1] + 1))
        noise = float(u(*self.radar_noise))
        rad = replace(
            radar,
            static_prob_scale=float(u(*self.static_prob_scale)),
            clutter_per_scan=float(u(*self.clutter_per_scan)),
            range_std=radar.range_std * noise,
            azimuth_std_deg=radar.azimuth_std_deg * noise,
            elevation_std_deg=radar.elevation_std_deg * noise,
            velocity_std=radar.velocity_std * noise,
        )
        return SensorSetup(
            "randomised",
            "a rig drawn by --sensor-randomise",
            lidar=lid,
            lidar_height=height,
            radar=rad,
            radar_scans=min(scans, max_scans),
        )


DEFAULT_RANDOMISATION = SensorRandomisation()
"""The ranges of ``--sensor-randomise``."""


def sensor_stream(seed: int, world_index: int) -> np.random.Generator:
    """World ``world_index``'s rig stream (module docstring)."""
    children = np.random.SeedSequence([seed, world_index]).spawn(SENSOR_STREAM + 1)
    return np.random.default_rng(children[SENSOR_STREAM])


__all__ = ["DEFAULT_RANDOMISATION", "SENSOR_STREAM", "SensorRandomisation", "sensor_stream"]
