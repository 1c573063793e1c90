"""A 4D imaging radar (VoD's ZF FRGen21-like) simulated against a :class:`~scenes.synth.world.World`.

Sensor
    Placed by ``radar_to_lidar`` (``(4, 4)``, radar frame -> LiDAR frame, e.g.
    ``scenes.geometry.calib.sensor_to_lidar(lidar_calib, radar_calib)``: about 2.5 m ahead of and 1.15 m below
    the LiDAR, behind the front bumper). Field of view +-60 degrees in azimuth, +-14 in elevation,
    100 m. The ego vehicle moves along +x at the world's ``ego_speed``; scan ``k`` (``time = -k``)
    is taken at ``t = -k * scan_period`` with the sensor ``ego_speed * k * scan_period`` further
    back and every actor moved back along its velocity, and its points are expressed in the LiDAR
    frame of the newest scan (``t = 0``), as VoD's accumulated ``radar_5frames``.

Detections
    A coarse grid of rays (0.4 x 1.5 degrees) finds what the radar can see.
    - Actors: an actor with at least one visible ray is detected with probability
      ``sigmoid(SNR / softness)``, ``SNR = RCS - 40 log10(r / 10 m) + snr_offset - weather loss``;
      its RCS depends on class and aspect (``front + (side - front) * sin^2`` of the angle between
      its heading and the line of sight: a car is ~+8 dBsm broadside, a pedestrian ~-12). A detected
      actor yields ``max(1, Poisson(points_at_10m * min(2, (10 / r)^0.5)))`` points drawn from its
      visible ray hits, each with the actor's RCS plus 4 dB noise.
    - Static surfaces: each visible ray hit is a detection with the material's probability times
      the SNR sigmoid (poles and signs often, facades sometimes, the road almost never).
    - Random clutter (uniform in the field of view, mostly near-zero Doppler) and multipath ghosts
      (a copy of an actor detection a few metres further along the same line of sight, weaker).
    Calibrated to View-of-Delft's single scans (issue 14): about 200-240 points in the camera's
    field of view, RCS p10 / p50 / p90 near -27 / -13 / +2 dBsm (mostly weak returns from the
    road, facades, vegetation and parked bicycles), 3-6 points on a pedestrian or cyclist within
    30 m; ``python -m bench.studies.sensor_stats`` measures them.
    Positions get range / azimuth / elevation noise in the radar frame.

Velocities (sign: positive = receding)
    With ``u`` the unit line of sight from the radar (at the scan's time) to the true point,
    the radar measures ``v_r = (v_ground - v_ego) . u + noise`` (micro-Doppler adds spread on limbs
    and pedals), and compensates ego motion with the *measured* direction ``u'`` (from the reported
    point): ``v_r_compensated = v_r + v_ego . u'``. So ``v_r_compensated`` is the ground velocity's
    line-of-sight projection up to noise, and ``v_r - v_r_compensated = -v_ego * u'_x`` exactly.

Output: ``(M, 7)`` float32 ``x, y, z, rcs, v_r, v_r_compensated, time`` in the LiDAR frame, the
newest scan first.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cache

import numpy as np

from scenes.synth.weather import CLEAR, Weather
from scenes.synth.world import RADAR_PROB, RADAR_RCS, RayCaster

STATIC, CLUTTER, GHOST = -1, -2, -3
"""``owner`` values of points that are not on an actor (actors are their index, >= 0)."""


@dataclass(frozen=True)
class RadarClassModel:
    """Radar signature of one actor class.

    Attributes:
        rcs_front: RCS (dBsm) seen head-on or from behind.
        rcs_side: RCS (dBsm) seen broadside.
        points_at_10m: Mean number of detections of an unoccluded actor at 10 m.
        micro_doppler: Extra spread of the radial velocity (m/s): limbs, pedals.
    """

    rcs_front: float
    rcs_side: float
    points_at_10m: float
    micro_doppler: float


ROAD_USER_SIGNATURES: tuple[tuple[str, RadarClassModel], ...] = (
    ("Truck", RadarClassModel(10.0, 20.0, 18.0, 0.05)),
    ("Bus", RadarClassModel(12.0, 22.0, 20.0, 0.05)),
    ("Trailer", RadarClassModel(8.0, 20.0, 18.0, 0.03)),
    ("ConstructionVehicle", RadarClassModel(8.0, 15.0, 14.0, 0.1)),
    ("Motorcycle", RadarClassModel(-3.0, 2.0, 6.0, 0.15)),
    ("Bicycle", RadarClassModel(-11.0, -6.0, 6.0, 0.2)),
    ("TrafficCone", RadarClassModel(-20.0, -20.0, 1.5, 0.0)),
    ("Barrier", RadarClassModel(0.0, -12.0, 4.0, 0.0)),
)
"""Radar signatures of the ``nuscenes`` class set's road users beyond the car and the pedestrian
(dBsm head-on, broadside; detections at 10 m; micro-Doppler): large flat metal sides make trucks,
buses and trailers the strongest targets (+20 dBsm broadside, against a car's +8), a
motorcycle lies between a car and a cyclist, a ridden bicycle is the ``vod`` cyclist, a plastic
cone barely reflects (-20 dBsm), and a barrier reflects off its broad face (its heading, the
thin axis, looks at that face) and little off its end."""


def scaled_signatures(
    signatures: tuple[tuple[str, RadarClassModel], ...], points: float
) -> tuple[tuple[str, RadarClassModel], ...]:
    """``signatures`` with ``points_at_10m`` times ``points`` (a sparser radar: the ARS-408)."""
    return tuple((n, replace(m, points_at_10m=m.points_at_10m * points)) for n, m in signatures)


@dataclass(frozen=True)
class RadarConfig:
    """The radar's field of view, resolution and noise.

    Attributes:
        azimuth_half_fov_deg, elevation_half_fov_deg: Field of view.
        azimuth_step_deg, elevation_step_deg: Visibility ray grid.
        min_range, max_range: m.
        range_std, azimuth_std_deg, elevation_std_deg: Position noise.
        velocity_std: Radial velocity noise (m/s).
        rcs_std: Per-detection RCS noise (dB).
        scan_period: Time between accumulated scans (s).
        snr_offset: SNR (dB) of a 0 dBsm target at 10 m.
        snr_softness: Width (dB) of the detection sigmoid.
        car, pedestrian, cyclist: Class signatures.
        road_users: Signatures of the other classes by name (:data:`ROAD_USER_SIGNATURES`).
        clutter_per_scan: Mean number of random clutter points per scan.
        ghost_prob: Probability that an actor detection has a multipath ghost.
        static_prob_scale: Factor on every static surface's detection probability (1: VoD's
            dense 4D radar; a cluster-list radar such as the ARS-408 reports far fewer).
        measures_elevation: False for a 2D radar (the ARS-408): the reported elevation is 0 in
            the radar frame plus ``elevation_std_deg`` noise, so ``z`` sits near the mounting
            height whatever the target's (clutter too).
    """

    azimuth_half_fov_deg: float = 60.0
    elevation_half_fov_deg: float = 14.0
    azimuth_step_deg: float = 0.4
    elevation_step_deg: float = 1.5
    min_range: float = 0.5
    max_range: float = 100.0
    range_std: float = 0.05
    azimuth_std_deg: float = 0.3
    elevation_std_deg: float = 1.0
    velocity_std: float = 0.1
    rcs_std: float = 4.0
    scan_period: float = 0.1
    snr_offset: float = 36.0
    snr_softness: float = 3.0
    car: RadarClassModel = RadarClassModel(0.0, 8.0, 10.0, 0.05)
    pedestrian: RadarClassModel = RadarClassModel(-13.0, -11.0, 5.0, 0.3)
    cyclist: RadarClassModel = RadarClassModel(-11.0, -6.0, 6.0, 0.2)
    clutter_per_scan: float = 40.0
    ghost_prob: float = 0.05
    static_prob_scale: float = 1.0
    measures_elevation: bool = True
    road_users: tuple[tuple[str, RadarClassModel], ...] = ROAD_USER_SIGNATURES

    def class_model(self, cls: str) -> RadarClassModel:
        """The signature of class ``cls`` (a class of any preset,
        :data:`scenes.geometry.classes.ALL_CLASSES`); KeyError naming it when it has none."""
        own = {"Car": self.car, "Pedestrian": self.pedestrian, "Cyclist": self.cyclist}
        if cls in own:
            return own[cls]
        for name, model in self.road_users:
            if name == cls:
                return model
        raise KeyError(f"radar: no signature for class {cls!r}")

    def without_noise(self) -> RadarConfig:
        """The same radar with exact positions, velocities and RCS, no clutter, no ghosts (tests)."""
        return replace(
            self,
            range_std=0.0,
            azimuth_std_deg=0.0,
            elevation_std_deg=0.0,
            velocity_std=0.0,
            rcs_std=0.0,
            clutter_per_scan=0.0,
            ghost_prob=0.0,
            car=replace(self.car, micro_doppler=0.0),
            pedestrian=replace(self.pedestrian, micro_doppler=0.0),
            cyclist=replace(self.cyclist, micro_doppler=0.0),
            road_users=tuple((n, replace(m, micro_doppler=0.0)) for n, m in self.road_users),
        )


@dataclass(frozen=True)
class RadarScan:
    """An accumulated radar point cloud.

    Attributes:
        points: ``(M, 7)`` float32 ``x, y, z, rcs, v_r, v_r_compensated, time``, LiDAR frame.
        owner: ``(M,)`` int: actor index, or :data:`STATIC`, :data:`CLUTTER`, :data:`GHOST`.
    """

    points: np.ndarray = field(repr=False)
    owner: np.ndarray = field(repr=False)


@cache
def _ray_grid(config: RadarConfig) -> np.ndarray:
    """``(R, 3)`` unit directions in the radar frame."""
    az_half, el_half = config.azimuth_half_fov_deg, config.elevation_half_fov_deg
    az = np.deg2rad(np.arange(-az_half, az_half + 1e-9, config.azimuth_step_deg))
    el = np.deg2rad(np.arange(-el_half, el_half + 1e-9, config.elevation_step_deg))
    e, a = np.meshgrid(el, az, indexing="ij")
    dirs = np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], -1).reshape(-1, 3)
    dirs.setflags(write=False)
    return dirs


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-x))


def _snr(rcs: np.ndarray, rng_m: np.ndarray, config: RadarConfig, weather: Weather) -> np.ndarray:
    return (
        rcs
        - 40.0 * np.log10(np.maximum(rng_m, 1.0) / 10.0)
        + config.snr_offset
        - weather.radar_loss_db
    )


@dataclass
class _Detections:
    """Detections of one scan before measurement noise (true points, LiDAR frame)."""

    points: list[np.ndarray] = field(default_factory=list)
    rcs: list[np.ndarray] = field(default_factory=list)
    v_ground: list[np.ndarray] = field(default_factory=list)  # (n, 3) ground velocity at the point
    owner: list[np.ndarray] = field(default_factory=list)
    extra_doppler: list[np.ndarray] = field(default_factory=list)  # (n,) micro-Doppler std

    def add(
        self,
        points: np.ndarray,
        rcs: np.ndarray | float,
        v_ground: np.ndarray,
        owner: int,
        extra_doppler: float,
    ) -> None:
        """Append ``(n, 3)`` points with their RCS, ground velocity ``(3,)``, owner and
        micro-Doppler spread (scalars are broadcast)."""
        n = len(points)
        self.points.append(np.asarray(points, float).reshape(n, 3))
        self.rcs.append(np.broadcast_to(np.asarray(rcs, float), (n,)))
        self.v_ground.append(np.broadcast_to(np.asarray(v_ground, float), (n, 3)))
        self.owner.append(np.broadcast_to(np.asarray(owner, np.int64), (n,)))
        self.extra_doppler.append(np.broadcast_to(np.asarray(extra_doppler, float), (n,)))

    def stacked(self) -> tuple[np.ndarray, ...]:
        if not self.points:
            return (
                np.zeros((0, 3)),
                np.zeros(0),
                np.zeros((0, 3)),
                np.zeros(0, np.int64),
                np.zeros(0),
            )
        return (
            np.concatenate(self.points),
            np.concatenate(self.rcs),
            np.concatenate(self.v_ground),
            np.concatenate(self.owner),
            np.concatenate(self.extra_doppler),
        )


def _scan(
    caster: RayCaster,
    radar_to_lidar: np.ndarray,
    scan_index: int,
    rng: np.random.Generator,
    config: RadarConfig,
    weather: Weather,
) -> tuple[np.ndarray, np.ndarray]:
    """One scan: ``(n, 7)`` points (LiDAR frame of t = 0) and their owners."""
    world = caster.world
    time = -scan_index * config.scan_period
    rot = radar_to_lidar[:3, :3]
    origin = radar_to_lidar[:3, 3] + world.ego_position(time)
    dirs = _ray_grid(config) @ rot.T
    hits = caster.cast(np.broadcast_to(origin, dirs.shape), dirs, time=time)
    in_range = hits.hit & (hits.distance >= config.min_range) & (hits.distance <= config.max_range)
    det = _Detections()

    # Static surfaces: per-ray detections.
    static = np.flatnonzero(in_range & (hits.owner < 0))
    mat = hits.material[static]
    dist = hits.distance[static]
    rcs = RADAR_RCS[mat]
    p = (
        RADAR_PROB[mat]
        * config.static_prob_scale
        * _sigmoid(_snr(rcs, dist, config, weather) / config.snr_softness)
    )
    chosen = static[rng.random(len(static)) < p]
    rcs_static = RADAR_RCS[hits.material[chosen]] + rng.normal(0.0, config.rcs_std, len(chosen))
    det.add(hits.points[chosen], rcs_static, np.zeros(3), STATIC, 0.0)

    # Actors: per-actor detection, then a few points among the visible ray hits.
    actor_rays = np.flatnonzero(in_range & (hits.owner >= 0))
    owners = hits.owner[actor_rays]
    for index in np.unique(owners):
        rays = actor_rays[owners == index]
        actor = world.actors[int(index)]
        model = config.class_model(actor.cls)
        centre = actor.box[:3].copy()
        centre[:2] += actor.velocity * time
        los = centre - origin
        r = float(np.linalg.norm(los))
        aspect = np.arctan2(los[1], los[0]) - actor.box[6]
        rcs_actor = model.rcs_front + (model.rcs_side - model.rcs_front) * np.sin(aspect) ** 2
        p_det = _sigmoid(
            _snr(np.array(rcs_actor), np.array(r), config, weather) / config.snr_softness
        )
        if rng.random() >= p_det:
            continue
        lam = (
            model.points_at_10m * min(2.0, (10.0 / max(r, 1.0)) ** 0.5) * min(1.0, len(rays) / 2.0)
        )
        n = max(1, int(rng.poisson(lam)))
        pick = rays[rng.choice(len(rays), size=n, replace=n > len(rays))]
        rcs_pts = rcs_actor + rng.normal(0.0, config.rcs_std, n)
        v = np.array([actor.velocity[0], actor.velocity[1], 0.0])
        det.add(hits.points[pick], rcs_pts, v, int(index), model.micro_doppler)

    points, rcs, v_ground, owner, extra = det.stacked()

    # Multipath ghosts: an actor detection seen again a few metres further away, weaker.
    is_actor = np.flatnonzero(owner >= 0)
    ghosts = is_actor[rng.random(len(is_actor)) < config.ghost_prob]
    if len(ghosts):
        los = points[ghosts] - origin
        los /= np.linalg.norm(los, axis=1, keepdims=True)
        shift = rng.uniform(1.5, 8.0, len(ghosts))[:, None]
        points = np.concatenate([points, points[ghosts] + los * shift])
        rcs = np.concatenate([rcs, rcs[ghosts] - rng.uniform(5.0, 12.0, len(ghosts))])
        v_ground = np.concatenate([v_ground, v_ground[ghosts]])
        owner = np.concatenate([owner, np.full(len(ghosts), GHOST)])
        extra = np.concatenate([extra, extra[ghosts]])

    # Measurement: true line of sight, Doppler with noise, then noisy position.
    los = points - origin
    rng_true = np.linalg.norm(los, axis=1)
    u_true = los / np.maximum(rng_true, 1e-9)[:, None]
    v_ego = world.ego_position(1.0)
    noise_scale = weather.radar_noise_scale
    v_std = np.hypot(config.velocity_std * noise_scale, extra)
    v_r = (
        np.einsum("ij,ij->i", v_ground - v_ego, u_true) + rng.normal(0.0, 1.0, len(points)) * v_std
    )

    local = u_true @ rot  # radar-frame directions
    az = np.arctan2(local[:, 1], local[:, 0])
    el = np.arcsin(np.clip(local[:, 2], -1.0, 1.0))
    if not config.measures_elevation:
        el = np.zeros_like(el)
    n = len(points)
    meas_r = rng_true + rng.normal(0.0, config.range_std * noise_scale, n)
    az = az + np.deg2rad(rng.normal(0.0, config.azimuth_std_deg * noise_scale, n))
    el = el + np.deg2rad(rng.normal(0.0, config.elevation_std_deg * noise_scale, n))
    u_meas = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1) @ rot.T
    measured = origin + u_meas * meas_r[:, None]
    v_comp = v_r + u_meas @ v_ego

    # Random clutter, uniform in the field of view, mostly with near-zero ground Doppler.
    m = int(rng.poisson(config.clutter_per_scan))
    c_r = rng.uniform(1.0, 60.0, m)
    c_az = np.deg2rad(rng.uniform(-config.azimuth_half_fov_deg, config.azimuth_half_fov_deg, m))
    c_el = np.deg2rad(rng.uniform(-5.0, config.elevation_half_fov_deg, m))
    if not config.measures_elevation:
        c_el = np.deg2rad(rng.normal(0.0, config.elevation_std_deg, m))
    c_u = np.stack([np.cos(c_el) * np.cos(c_az), np.cos(c_el) * np.sin(c_az), np.sin(c_el)], -1)
    c_u = c_u @ rot.T
    c_comp = np.where(rng.random(m) < 0.8, rng.normal(0.0, 0.2, m), rng.uniform(-4.0, 4.0, m))
    c_rcs = rng.uniform(-35.0, -15.0, m)

    keep = (meas_r >= config.min_range) & (meas_r <= config.max_range)
    out = np.empty((int(keep.sum()) + m, 7))
    k = int(keep.sum())
    out[:k, :3] = measured[keep]
    out[:k, 3] = rcs[keep]
    out[:k, 4] = v_r[keep]
    out[:k, 5] = v_comp[keep]
    out[k:, :3] = origin + c_u * c_r[:, None]
    out[k:, 3] = c_rcs
    out[k:, 4] = c_comp - c_u @ v_ego
    out[k:, 5] = c_comp
    out[:, 6] = -scan_index
    return out, np.concatenate([owner[keep], np.full(m, CLUTTER)])


def simulate_radar(
    caster: RayCaster,
    radar_to_lidar: np.ndarray,
    rng: np.random.Generator,
    config: RadarConfig = RadarConfig(),
    weather: Weather = CLEAR,
    scans: int = 5,
) -> RadarScan:
    """``scans`` accumulated radar scans of ``caster.world`` (see the module docstring).

    Args:
        radar_to_lidar: ``(4, 4)`` radar frame -> LiDAR frame.
        scans: 1, 3 or 5 (any positive number works); scan ``k`` has ``time = -k``.
    """
    if scans < 1:
        raise ValueError(f"scans must be >= 1, got {scans}")
    radar_to_lidar = np.asarray(radar_to_lidar, dtype=np.float64)
    if radar_to_lidar.shape != (4, 4):
        raise ValueError(f"radar_to_lidar must be (4, 4), got {radar_to_lidar.shape}")
    parts = [_scan(caster, radar_to_lidar, k, rng, config, weather) for k in range(scans)]
    points = np.concatenate([p for p, _ in parts]).astype(np.float32)
    owner = np.concatenate([o for _, o in parts])
    return RadarScan(points=points, owner=owner)
