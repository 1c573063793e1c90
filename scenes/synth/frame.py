"""One synthetic frame: the generation settings, the per-world random streams, and a world built
and sensed (LiDAR, accumulated radar, camera image) with its prompts drawn over the sensed actors.
:mod:`scenes.synth` writes such frames as a Talk2Radar root (and re-exports these names).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from scenes.geometry.calib import Calibration, vod_lidar_calibration, vod_radar_calibration
from scenes.geometry.classes import PRESETS
from scenes.geometry.projection import scale_calibration
from scenes.language.prompts import LANGUAGES, PHRASINGS, Prompt, PromptConfig, generate_prompts
from scenes.synth.camera import CameraConfig, render_image
from scenes.synth.lidar import LidarConfig, LidarScan, simulate_lidar
from scenes.synth.radar import RadarConfig, RadarScan, simulate_radar
from scenes.synth.randomise import DEFAULT_RANDOMISATION, sensor_stream
from scenes.synth.sensors import SENSOR_SETS, SensorSet, simulate_radars
from scenes.synth.sensors import sensor_set as _preset
from scenes.synth.sequence import world_at
from scenes.synth.setups import IN_DOMAIN, SETUPS, SensorSetup, lidar_calibration_at, sensor_setup
from scenes.synth.weather import WEATHERS, Weather
from scenes.synth.world import RayCaster, World, WorldConfig, generate_world
from scenes.talk2radar.poses import FRAME_RATE
from scenes.talk2radar.writer import RADAR_SCANS
from scenes.utils.cli import option

MIXED = "mixed"
MIXED_WEATHER = (("clear", 0.6), ("rain", 0.2), ("fog", 0.2))


MAX_SEQUENCE_LENGTH = 100
"""Longest ``--sequence-length`` (10 s at 10 Hz: straight-line motion is meant for short runs)."""


class SynthError(ValueError):
    """Bad generation settings or an output folder that cannot be resumed."""


GENERATOR_VERSION = 2
"""Bumped whenever the same settings start to give other worlds or sensor data. Recorded in the
manifest, so that an interrupted root is never finished with another generator's worlds (a root
written before versions were recorded counts as version 1). 2: issue 14's second calibration
(the HDL-64's 50 m range for a 10 % target, 0.08 degree azimuth step over the whole forward half
instead of +-45 degrees, dark clothing, lead-car gaps, turning cyclists)."""


@dataclass(frozen=True)
class SynthSettings:
    """What determines the generated content (``--frames`` and the splits do not).

    Attributes:
        seed: Base seed; world ``i`` uses ``SeedSequence([seed, i])``.
        weather: ``clear``, ``rain``, ``fog`` or ``mixed``.
        radar_scans: Accumulated radar scans, 1, 3 or 5.
        prompts_per_world: Prompts (samples) drawn per world (fewer when the world has fewer).
        min_lidar_points, min_radar_points: An actor can be a referent when it has at least this
            many LiDAR points or radar points (see :func:`synthesize`).
        phrasing: Prompt wording stream, ``train``, ``heldout`` or ``all``
            (``scenes.language.prompts.PromptConfig.phrasing``).
        camera: The camera image's settings, or None for no image (``--no-camera``).
        sequence_length: Consecutive 10 Hz frames written per world (``--sequence-length``;
            :func:`synthesize_sequence`); 1: one frame, as before sequences existed.
        language: Prompt language, ``base`` or ``extended`` (``--language``;
            ``scenes.language.prompts.PromptConfig.language``): extended adds out-of-class,
            unsatisfiable, negation, exclusion, ordinal, relation and counting prompts, some of
            whose samples have no referent (an empty ``label_2``).
        command_share: Share of single-referent prompts phrased as driving commands
            (``--command-share``; ``scenes.language.prompts.PromptConfig.command_share``).
        sensors: ``vod`` (the default: ``lidar``, ``radar``, ``world`` and ``camera`` as given)
            or ``nuscenes`` (:data:`scenes.synth.sensors.NUSCENES`: its LiDAR replaces ``lidar``,
            its mounting height ``world.lidar_height``, its camera size ``camera.base_size``, and
            its five radars, merged in the LiDAR frame, replace ``radar``).
        classes: The class set the world is populated for and the prompts name (``--classes``;
            :data:`scenes.geometry.classes.PRESETS`): ``vod`` (the default: cars, pedestrians,
            cyclists, ``world`` as given) or ``nuscenes`` (its 10 classes: ``world.classes``,
            :mod:`scenes.synth.world.road_users`, and ``PromptConfig.classes``).
        sensor_setup: A named rig of :data:`scenes.synth.setups.SETUPS` (``--sensor-setup``;
            ``vod``: the rig above, unchanged): every world of the seed sensed through it (its
            LiDAR, height, radar and street; ``radar-1scan`` makes ``radar_scans`` 1).
        sensor_randomise: Each world sensed through a rig drawn by
            :data:`scenes.synth.randomise.DEFAULT_RANDOMISATION` (``--sensor-randomise``).
    """

    seed: int = option(0, help="base seed (default %(default)s)")
    weather: str = option(
        "clear",
        choices=(*WEATHERS, MIXED),
        help="weather of every world, or mixed (60/20/20 %% clear/rain/fog); default %(default)s",
    )
    radar_scans: int = option(
        5,
        choices=sorted(RADAR_SCANS),
        help="accumulated radar scans: tree radar, radar_3frames or radar_5frames (default "
        "%(default)s)",
    )
    prompts_per_world: int = option(2, help="samples per world (default %(default)s)")
    min_lidar_points: int = option(3, cli=False)
    min_radar_points: int = option(1, cli=False)
    world: WorldConfig = option(default_factory=WorldConfig, cli=False)
    lidar: LidarConfig = option(default_factory=LidarConfig, cli=False)
    radar: RadarConfig = option(default_factory=RadarConfig, cli=False)
    phrasing: str = option(
        "train",
        choices=PHRASINGS,
        help="prompt wording: train phrasings, held-out phrasings (for measuring generalisation "
        "to other wording) or all (default %(default)s)",
    )
    camera: CameraConfig | None = option(default_factory=CameraConfig, cli=False)
    sequence_length: int = option(
        1,
        metavar="N",
        help="consecutive 10 Hz frames per world: actors move with their velocities, the ego "
        "with its speed, each frame gets a View-of-Delft pose file (default %(default)s: single "
        "frames)",
    )
    language: str = option(
        "base",
        choices=LANGUAGES,
        help="prompt language: base (attribute prompts) or extended (also out-of-class, "
        "unsatisfiable, negation, exclusion, ordinal, relation and counting prompts; some "
        "samples then have no referent: an empty label_2); default %(default)s",
    )

    command_share: float = option(
        0.0,
        metavar="S",
        help="share of single-referent prompts phrased as driving commands around their "
        "description, Talk2Car style ('pull over behind the cyclist on the right'; "
        "scenes.language.prompts.commands); default %(default)s",
    )
    people_share: float = option(
        0.0,
        metavar="P",
        help="share of those commands said the way people say them: the manoeuvre first, "
        "colours and clothes, people's words for the class, context first "
        "(scenes.language.prompts.people); default %(default)s",
    )

    sensors: str = option(
        "vod",
        choices=SENSOR_SETS,
        help="sensor set: vod (64-beam LiDAR, one 4D radar, 1936 x 1216 camera) or nuscenes "
        "(32-beam HDL-32E-like LiDAR 1.84 m up, five sparse 2D ARS-408-like radars merged in the "
        "LiDAR frame, 1600 x 900 CAM_FRONT; scenes.synth.sensors); default %(default)s",
    )

    classes: str = option(
        "vod",
        choices=tuple(PRESETS),
        help="class set of the world and the prompts: vod (cars, pedestrians, cyclists) or "
        "nuscenes (cars, trucks, buses, trailers, construction vehicles, pedestrians, "
        "motorcycles, bicycles, traffic cones, barriers; scenes.synth.world.road_users); "
        "default %(default)s",
    )

    sensor_setup: str = option(
        IN_DOMAIN.name,
        choices=tuple(SETUPS),
        help="sense every world through this rig (scenes.synth.setups; held-out rigs of issue "
        "38: other LiDARs, mounts, intensities, radars, street densities); default %(default)s",
    )
    sensor_randomise: bool = option(
        False,
        help="sense each world through a rig drawn at random (beams and pattern, mounting height "
        "and pitch, dropout, intensity scale, range noise, radar density, noise and scans; "
        "scenes.synth.randomise), never a held-out rig's values",
    )

    def __post_init__(self) -> None:
        if self.classes not in PRESETS:
            raise SynthError(f"classes must be one of {list(PRESETS)}, got {self.classes!r}")
        if self.world.classes != self.classes:
            object.__setattr__(self, "world", replace(self.world, classes=self.classes))
        self._check_rig()
        if self.sensors not in SENSOR_SETS:
            raise SynthError(f"sensors must be one of {list(SENSOR_SETS)}, got {self.sensors!r}")
        preset = _preset(self.sensors)
        if preset is not None:
            object.__setattr__(self, "lidar", preset.lidar)
            object.__setattr__(self, "world", replace(self.world, lidar_height=preset.lidar_height))
            if self.camera is not None and self.camera.base_size != preset.image_size:
                try:
                    camera = replace(self.camera, base_size=preset.image_size)
                except ValueError as exc:
                    raise SynthError(f"--sensors {self.sensors} camera: {exc}") from exc
                object.__setattr__(self, "camera", camera)
        if not 0.0 <= self.command_share <= 1.0:
            raise SynthError(f"command_share must be in [0, 1], got {self.command_share}")
        if not 0.0 <= self.people_share <= 1.0:
            raise SynthError(f"people_share must be in [0, 1], got {self.people_share}")
        if self.phrasing not in PHRASINGS:
            raise SynthError(f"phrasing must be one of {list(PHRASINGS)}, got {self.phrasing!r}")
        if self.language not in LANGUAGES:
            raise SynthError(f"language must be one of {list(LANGUAGES)}, got {self.language!r}")
        if self.seed < 0:
            raise SynthError(f"seed must be >= 0, got {self.seed}")
        if self.weather != MIXED and self.weather not in WEATHERS:
            raise SynthError(f"weather must be one of {[*WEATHERS, MIXED]}, got {self.weather!r}")
        if self.radar_scans not in RADAR_SCANS:
            raise SynthError(f"radar_scans must be 1, 3 or 5, got {self.radar_scans}")
        if self.prompts_per_world < 1:
            raise SynthError(f"prompts_per_world must be >= 1, got {self.prompts_per_world}")
        if not 1 <= self.sequence_length <= MAX_SEQUENCE_LENGTH:
            raise SynthError(
                f"sequence_length must be in [1, {MAX_SEQUENCE_LENGTH}], got {self.sequence_length}"
            )

    def _check_rig(self) -> None:
        """Refuse contradicting rig options; a single-scan set-up sets ``radar_scans`` to 1."""
        if self.sensor_setup not in SETUPS:
            raise SynthError(
                f"sensor_setup must be one of {list(SETUPS)}, got {self.sensor_setup!r}"
            )
        named = self.sensor_setup != IN_DOMAIN.name
        if (named or self.sensor_randomise) and self.sensors != "vod":
            raise SynthError("--sensor-setup and --sensor-randomise change the vod sensors only")
        if named and self.sensor_randomise:
            raise SynthError("--sensor-setup and --sensor-randomise exclude each other")
        if named and sensor_setup(self.sensor_setup).radar_scans == 1:
            if self.radar_scans not in (1, 5):
                raise SynthError(
                    f"--sensor-setup {self.sensor_setup} has one radar scan, not {self.radar_scans}"
                )
            object.__setattr__(self, "radar_scans", 1)
        if self.sensor_randomise and self.radar_scans < DEFAULT_RANDOMISATION.radar_scans[0]:
            raise SynthError(
                "--sensor-randomise needs --radar-scans 3 or 5 (it draws 2 scans or more)"
            )

    def world_setup(self, world_index: int) -> SensorSetup | None:
        """The rig world ``world_index`` is sensed through: None for the default rig (the
        configs as given), the named set-up, or the one drawn for this world."""
        if self.sensor_randomise:
            rng = sensor_stream(self.seed, world_index)
            return DEFAULT_RANDOMISATION.draw(rng, self.radar_scans, self.lidar, self.radar)
        if self.sensor_setup != IN_DOMAIN.name:
            return replace(sensor_setup(self.sensor_setup), radar_scans=self.radar_scans)
        return None

    def key(self) -> dict:
        """The settings recorded in (and compared with) the manifest."""
        return {
            "seed": self.seed,
            "weather": self.weather,
            "radar_scans": self.radar_scans,
            "prompts_per_world": self.prompts_per_world,
            "generator": GENERATOR_VERSION,
            # Only when not the default, so roots written before the option resume as before.
            **({"phrasing": self.phrasing} if self.phrasing != "train" else {}),
            # Only with a camera: a root without images records what it did before cameras.
            **({"camera": self.camera.key()} if self.camera is not None else {}),
            **({"sequence_length": self.sequence_length} if self.sequence_length > 1 else {}),
            **({"language": self.language} if self.language != "base" else {}),
            **({"command_share": self.command_share} if self.command_share else {}),
            **({"people_share": self.people_share} if self.people_share else {}),
            **({"sensors": self.sensors} if self.sensors != "vod" else {}),
            **({"classes": self.classes} if self.classes != "vod" else {}),
            **({"sensor_setup": self.sensor_setup} if self.sensor_setup != IN_DOMAIN.name else {}),
            **({"sensor_randomise": True} if self.sensor_randomise else {}),
        }

    def sensor_set(self) -> SensorSet | None:
        """The sensor preset (None: ``vod``, the configs as given)."""
        return _preset(self.sensors)

    def calibrations(self, setup: SensorSetup | None = None) -> tuple[Calibration, Calibration]:
        """The LiDAR and radar calibrations written: VoD's, with ``P2`` scaled to the camera
        image (:attr:`scenes.synth.camera.CameraConfig.image_scale`) where there is one; with
        ``--sensors nuscenes`` the preset's camera, and the radar calibration equal to the
        LiDAR's: the merged radar cloud is in the LiDAR frame). With a rig (``setup``, default
        the named ``sensor_setup``) of another LiDAR height, the LiDAR's is moved to it
        (:func:`scenes.synth.setups.lidar_calibration_at`: camera and radar stay on the car)."""
        if setup is None and self.sensor_setup != IN_DOMAIN.name:
            setup = sensor_setup(self.sensor_setup)
        lidar, radar = self._base_calibrations()
        if setup is not None:
            lidar = lidar_calibration_at(lidar, setup.lidar_height)
        return lidar, radar

    def _base_calibrations(self) -> tuple[Calibration, Calibration]:
        preset = self.sensor_set()
        if preset is not None:
            scale = self.camera.image_scale if self.camera is not None else 1.0
            calib = preset.calibration(scale)
            return calib, calib
        lidar, radar = vod_lidar_calibration(), vod_radar_calibration()
        if self.camera is None or self.camera.image_scale == 1.0:
            return lidar, radar
        scale = self.camera.image_scale
        return scale_calibration(lidar, scale), scale_calibration(radar, scale)


@dataclass(frozen=True)
class StageTimes:
    """Seconds spent per stage on one world."""

    world: float = 0.0
    lidar: float = 0.0
    radar: float = 0.0
    prompts: float = 0.0
    camera: float = 0.0


@dataclass(frozen=True)
class SynthFrame:
    """One sensed world and its prompts.

    Attributes:
        world: The world (actors, meshes).
        weather: Its weather.
        lidar: ``points (N, 4)`` LiDAR frame, and the owner of each point.
        radar: ``points (M, 7)`` LiDAR frame, and the owner of each point.
        prompts: Up to ``prompts_per_world`` prompts.
        sensed: Indices of the actors the prompts could refer to (seen by a sensor).
        times: Stage timings.
        image: ``(H, W, 3)`` uint8 camera image at ``t = 0`` (None without a camera, or when the
            world yielded no prompt and so is not written).
        setup: The rig it was sensed through (:meth:`SynthSettings.world_setup`; None: the
            settings' own).
    """

    world: World
    weather: Weather
    lidar: LidarScan
    radar: RadarScan
    prompts: tuple[Prompt, ...]
    sensed: tuple[int, ...]
    times: StageTimes
    image: np.ndarray | None = None
    setup: SensorSetup | None = None


def world_streams(seed: int, world_index: int) -> dict[str, np.random.Generator]:
    """The independent random streams of world ``world_index`` (a stream added later is spawned
    last, so the earlier ones stay as they were)."""
    children = np.random.SeedSequence([seed, world_index]).spawn(6)
    names = ("world", "weather", "lidar", "radar", "prompts", "camera")
    return {name: np.random.default_rng(s) for name, s in zip(names, children, strict=True)}


def _pick_weather(settings: SynthSettings, rng: np.random.Generator) -> Weather:
    if settings.weather != MIXED:
        return WEATHERS[settings.weather]
    names, probs = zip(*MIXED_WEATHER, strict=True)
    return WEATHERS[names[int(rng.choice(len(names), p=probs))]]


def sensed_actor_ids(
    lidar: LidarScan, radar: RadarScan, min_lidar_points: int, min_radar_points: int
) -> tuple[int, ...]:
    """Indices of the actors with at least ``min_lidar_points`` LiDAR or ``min_radar_points``
    radar points (any scan)."""
    n = int(max(lidar.owner.max(initial=-1), radar.owner.max(initial=-1))) + 1
    lidar_count = np.bincount(lidar.owner[lidar.owner >= 0], minlength=n)
    radar_count = np.bincount(radar.owner[radar.owner >= 0], minlength=n)
    seen = (lidar_count >= min_lidar_points) | (radar_count >= min_radar_points)
    return tuple(int(i) for i in np.flatnonzero(seen))


def synthesize(
    settings: SynthSettings,
    world_index: int,
    radar_to_lidar: np.ndarray,
    camera_calib: Calibration | None = None,
) -> SynthFrame:
    """Build and sense world ``world_index``, draw its prompts and, where it has some and the
    settings have a camera, render its camera image.

    Prompts are drawn over the *sensed* actors only (:func:`sensed_actor_ids`): an actor hidden
    from both sensors (occluded, or beyond the LiDAR's reach in fog and missed by the radar) is
    as invisible to the prompt as it would be to an annotator.

    Args:
        radar_to_lidar: ``(4, 4)`` radar -> LiDAR transform (``scenes.geometry.calib.sensor_to_lidar``).
        camera_calib: The LiDAR calibration of the image (default ``settings.calibrations()``).
    """
    return synthesize_sequence(settings, world_index, radar_to_lidar, camera_calib, length=1)[0]


def synthesize_sequence(
    settings: SynthSettings,
    world_index: int,
    radar_to_lidar: np.ndarray,
    camera_calib: Calibration | None = None,
    length: int = 1,
) -> list[SynthFrame]:
    """``length`` consecutive frames of world ``world_index`` at :data:`scenes.talk2radar.poses.FRAME_RATE`
    (:func:`scenes.synth.sequence.world_at`: actors moved by their velocities, the ego by its speed),
    each sensed and prompted as :func:`synthesize` does one; frame 0 is exactly
    :func:`synthesize`'s frame. Frame ``k > 0`` draws its sensors, prompts and image from
    ``SeedSequence([seed, world_index, k])``; the weather stays frame 0's.
    """
    rngs = world_streams(settings.seed, world_index)
    setup = settings.world_setup(world_index)
    world_config = settings.world
    if setup is not None:
        world_config = replace(world_config, lidar_height=setup.lidar_height, street=setup.street)
    t0 = time.perf_counter()
    first = generate_world(rngs["world"], world_index, world_config)
    weather = _pick_weather(settings, rngs["weather"])
    built = time.perf_counter() - t0
    frames = []
    for k in range(length):
        world = first if k == 0 else world_at(first, k / FRAME_RATE)
        streams = rngs if k == 0 else frame_streams(settings.seed, world_index, k)
        frame = _sense(settings, setup, world, weather, streams, radar_to_lidar, camera_calib)
        if k == 0:
            frame = replace(frame, times=replace(frame.times, world=built))
        frames.append(frame)
    return frames


def sense_world(settings: SynthSettings, world: World, radar_to_lidar: np.ndarray) -> SynthFrame:
    """Sense a world built elsewhere (e.g. :func:`generate_world`'s, with actors taken out) as
    :func:`synthesize` senses world ``world.world_id`` of ``settings``: the same weather and
    sensor streams, no camera image. Its prompts are drawn over the sensed actors as usual."""
    rngs = world_streams(settings.seed, world.world_id)
    weather = _pick_weather(settings, rngs["weather"])
    setup = settings.world_setup(world.world_id)
    settings = replace(settings, camera=None)
    return _sense(settings, setup, world, weather, rngs, radar_to_lidar, None)


def frame_streams(seed: int, world_index: int, frame: int) -> dict[str, np.random.Generator]:
    """The random streams of frame ``frame >= 1`` of a sequence (named as :func:`world_streams`;
    the world and weather streams go unused: a sequence keeps its first frame's)."""
    children = np.random.SeedSequence([seed, world_index, frame]).spawn(6)
    names = ("world", "weather", "lidar", "radar", "prompts", "camera")
    return {name: np.random.default_rng(s) for name, s in zip(names, children, strict=True)}


def _sense(
    settings: SynthSettings,
    setup: SensorSetup | None,
    world: World,
    weather: Weather,
    rngs: dict[str, np.random.Generator],
    radar_to_lidar: np.ndarray,
    camera_calib: Calibration | None,
) -> SynthFrame:
    """Sense one world (LiDAR, radar, prompts over the sensed actors, the camera image) through
    ``setup`` (None: the settings' sensors)."""
    t1 = time.perf_counter()
    caster = RayCaster(world)
    lidar_config = settings.lidar if setup is None else setup.lidar
    lidar = simulate_lidar(caster, rngs["lidar"], lidar_config, weather)
    t2 = time.perf_counter()
    preset = settings.sensor_set()
    scans = settings.radar_scans if setup is None else setup.radar_scans
    mounts = preset.radars if preset is not None else () if setup is None else setup.radar_mounts
    if mounts:
        radar = simulate_radars(caster, mounts, rngs["radar"], weather, scans)
    else:
        radar_config = settings.radar if setup is None else setup.radar
        radar = simulate_radar(caster, radar_to_lidar, rngs["radar"], radar_config, weather, scans)
    t3 = time.perf_counter()
    sensed = sensed_actor_ids(lidar, radar, settings.min_lidar_points, settings.min_radar_points)
    candidates = [world.actors[i] for i in sensed]
    prompts = tuple(
        generate_prompts(
            candidates,
            rngs["prompts"],
            settings.prompts_per_world,
            config=PromptConfig(
                phrasing=settings.phrasing,
                language=settings.language,
                command_share=settings.command_share,
                people_share=settings.people_share,
                classes=settings.classes,
            ),
        )
    )
    t4 = time.perf_counter()
    image = None
    if settings.camera is not None and prompts:
        calib = camera_calib if camera_calib is not None else settings.calibrations()[0]
        size = settings.camera.image_size
        image = render_image(world, calib, size, weather, rngs["camera"], settings.camera)
    t5 = time.perf_counter()
    times = StageTimes(lidar=t2 - t1, radar=t3 - t2, prompts=t4 - t3, camera=t5 - t4)
    return SynthFrame(world, weather, lidar, radar, prompts, sensed, times, image, setup)
