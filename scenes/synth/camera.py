"""The synthetic camera: an RGB image of a :class:`~scenes.synth.world.World`, ray-cast with embree
through the same triangle meshes the LiDAR and the radar see, at the pose and intrinsics of a
frame's calibration (``P2``, ``R0_rect``, ``Tr_velo_to_cam``).

Image model
    One ray per ``ray_step x ray_step`` block of pixels, through the block's centre (continuous
    pixel convention: the image covers ``[0, W] x [0, H]``, see :mod:`scenes.geometry.projection`), against
    the static scene and the actors at the frame's time ``t = 0``; the ray image is upsampled to
    the full size bilinearly (centres aligned), so geometry sits where ``P2`` puts it. A hit takes
    its face's colour (per material, see :data:`STATIC_COLOURS`; cars, clothing, skin and bicycle
    frames of each actor drawn from small palettes) shaded as a two-sided Lambertian surface under
    a sun (azimuth and elevation drawn per world) plus a sky-light term that favours upward faces.
    No shadows. A miss shows the sky: a gradient from the horizon to the zenith.

Weather
    Fog and rain veil the image with the extinction coefficient that degrades the LiDAR
    (:attr:`~scenes.synth.weather.Weather.lidar_extinction`, one way): a surface ``d`` metres away keeps
    ``exp(-extinction * d)`` of its colour and takes the rest from the horizon colour (Koschmieder),
    so fog (0.12 /m) hides what lies beyond 20-25 m as it does for the LiDAR; clear air has a
    faint haze (:attr:`CameraConfig.haze`). Both overcast the sky (grey, little direct sun) and dim
    the scene; rain also darkens the wet ground.

Determinism: all random choices (sun, colour tints, palettes) come from the ``rng`` given; the same
world, calibration, weather and seed give the same pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh
from PIL import Image

from scenes.geometry.calib import IMAGE_SIZE, Calibration
from scenes.geometry.projection import image_size_at, scale_calibration
from scenes.synth.weather import Weather
from scenes.synth.world import Mat, TaggedMesh, World
from scenes.utils.cli import option

CAMERA_SCALES = (1.0, 0.5, 0.25, 0.125)
"""``--camera-scale`` values: the image sizes that divide VoD's exactly."""
CAMERA_RAY_STEPS = (1, 2, 4)
"""``--camera-ray-step`` values."""


@dataclass(frozen=True)
class CameraConfig:
    """How the synthetic camera image is made.

    Attributes:
        image_scale: Written image size relative to VoD's 1936 x 1216 (1, 1/2, 1/4 or 1/8); the
            calibration written with it has ``P2`` scaled to match (:func:`scenes.geometry.projection.
            scale_calibration`) and ``label_2``'s 2D boxes are clipped to that size.
        ray_step: One ray per ``ray_step x ray_step`` pixels (1 = one per pixel); must divide
            the image size.
        jpeg_quality: JPEG quality of ``image_2/<id>.jpg`` (1..95).
        sun_elevation_deg: Range of the sun's elevation, drawn per world (degrees).
        haze: Extinction coefficient (1/m) of clear air for the veil; the weather's LiDAR
            extinction is used where larger.
        base_size: ``(width, height)`` at scale 1: VoD's 1936 x 1216, or the sensor set's
            (``scenes.synth.sensors``: nuScenes' CAM_FRONT is 1600 x 900).
    """

    image_scale: float = option(
        1.0,
        flag="--camera-scale",
        choices=CAMERA_SCALES,
        help="camera image size relative to VoD's 1936 x 1216 (P2 scaled to match; default "
        "%(default)s)",
    )
    ray_step: int = option(
        2,
        flag="--camera-ray-step",
        choices=CAMERA_RAY_STEPS,
        help="one camera ray per N x N pixels, upsampled (default %(default)s; 4 is about twice "
        "as fast)",
    )
    jpeg_quality: int = option(90, cli=False)
    sun_elevation_deg: tuple[float, float] = option((20.0, 60.0), cli=False)
    haze: float = option(0.003, cli=False)
    base_size: tuple[int, int] = option(IMAGE_SIZE, cli=False)

    def __post_init__(self) -> None:
        # raises for a scale that is not exact
        width, height = image_size_at(self.image_scale, self.base_size)
        if self.ray_step < 1 or width % self.ray_step or height % self.ray_step:
            raise ValueError(
                f"ray_step must be >= 1 and divide the {width} x {height} image, got {self.ray_step}"
            )
        if not 1 <= self.jpeg_quality <= 95:
            raise ValueError(f"jpeg_quality must be in 1..95, got {self.jpeg_quality}")
        lo, hi = self.sun_elevation_deg
        if not 0.0 < lo <= hi <= 90.0:
            raise ValueError(f"sun_elevation_deg must be 0 < lo <= hi <= 90, got {(lo, hi)}")

    @property
    def image_size(self) -> tuple[int, int]:
        """``(width, height)`` of the written image."""
        return image_size_at(self.image_scale, self.base_size)

    def key(self) -> dict:
        """What determines the pixels (recorded in the synth manifest)."""
        return {
            "image_scale": self.image_scale,
            "ray_step": self.ray_step,
            "jpeg_quality": self.jpeg_quality,
            "sun_elevation_deg": list(self.sun_elevation_deg),
            "haze": self.haze,
            # Only when not VoD's, so roots written before the option resume as before.
            **({"base_size": list(self.base_size)} if self.base_size != IMAGE_SIZE else {}),
        }


def _rgb(*values: tuple[float, float, float]) -> np.ndarray:
    return np.array(values, dtype=np.float32)


STATIC_COLOURS = _rgb(
    (0.36, 0.36, 0.37),  # ASPHALT
    (0.92, 0.92, 0.90),  # MARKING
    (0.62, 0.20, 0.18),  # BIKE_PATH: red cycle lanes and paths
    (0.66, 0.63, 0.58),  # PAVING: sidewalks, paved verges
    (0.36, 0.52, 0.24),  # GRASS
    (0.42, 0.35, 0.27),  # SOIL
    (0.52, 0.34, 0.26),  # BRICK
    (0.72, 0.71, 0.68),  # CONCRETE: kerbs, walls, buildings
    (0.26, 0.36, 0.52),  # GLASS_FACADE
    (0.45, 0.47, 0.50),  # METAL: poles, lights, racks
    (0.15, 0.32, 0.72),  # SIGN
    (0.32, 0.24, 0.17),  # BARK
    (0.22, 0.40, 0.16),  # FOLIAGE: trees, hedges
    (0.16, 0.16, 0.18),  # PAINT_DARK (parked mopeds; cars use CAR_DARK)
    (0.82, 0.82, 0.80),  # PAINT_LIGHT (parked mopeds; cars use CAR_LIGHT)
    (0.10, 0.12, 0.15),  # CAR_GLASS
    (0.06, 0.06, 0.06),  # RUBBER
    (0.22, 0.22, 0.28),  # CLOTHING (panniers; people use CLOTHES)
    (0.85, 0.66, 0.55),  # SKIN
    (0.12, 0.12, 0.13),  # BIKE_FRAME (parked bicycles; ridden ones use BIKE_FRAMES)
    (0.14, 0.14, 0.16),  # CLOTHING_DARK (people use CLOTHES: near-infrared darkness is not colour)
)
"""Display RGB in ``[0, 1]`` per :class:`~scenes.synth.world.Mat` (before shading), up to
``CLOTHING_DARK``; each gets a per-world tint."""
ROAD_USER_COLOURS = _rgb(
    (0.95, 0.40, 0.06),  # CONE_ORANGE
    (0.93, 0.72, 0.10),  # WORKS_YELLOW
)
"""Display RGB of the materials after ``CLOTHING_DARK`` (the road users of the ``nuscenes``
class set), untinted: a tint would draw from the world's camera stream and move every image of
the default class set."""

CAR_DARK = _rgb((0.07, 0.07, 0.08), (0.20, 0.21, 0.23), (0.10, 0.14, 0.32), (0.38, 0.06, 0.07))
CAR_LIGHT = _rgb((0.90, 0.90, 0.88), (0.70, 0.72, 0.74), (0.55, 0.66, 0.80), (0.78, 0.13, 0.11))
CLOTHES = _rgb(
    (0.12, 0.12, 0.14),
    (0.15, 0.20, 0.38),
    (0.45, 0.45, 0.47),
    (0.62, 0.12, 0.12),
    (0.70, 0.60, 0.45),
    (0.20, 0.35, 0.22),
    (0.85, 0.80, 0.20),
)
SKINS = _rgb((0.93, 0.75, 0.64), (0.82, 0.62, 0.50), (0.60, 0.42, 0.30), (0.38, 0.25, 0.18))
BIKE_FRAMES = _rgb((0.10, 0.10, 0.11), (0.15, 0.30, 0.20), (0.18, 0.25, 0.50), (0.85, 0.82, 0.72))
"""Per-actor palettes: car paint (dark or light, as the mesh's material says), clothes, skin and
bicycle frame; each actor draws one entry of each."""

WET_GROUND = (Mat.ASPHALT, Mat.MARKING, Mat.BIKE_PATH, Mat.PAVING)
"""Materials darkened by rain."""

SKY_DEPTH = 50.0
"""Metres of air the sky's gradient is seen through (see :func:`lighting_for`)."""

_SKY_CLEAR = _rgb((0.78, 0.85, 0.93), (0.33, 0.52, 0.82))  # horizon, zenith
_SKY_OVERCAST = _rgb((0.74, 0.75, 0.77), (0.58, 0.60, 0.63))


@dataclass(frozen=True)
class Lighting:
    """The light of one image.

    Attributes:
        sun: ``(3,)`` unit vector towards the sun, LiDAR frame.
        sun_strength: Weight of the Lambertian sun term.
        ambient: Weight of the sky-light term.
        horizon, zenith: ``(3,)`` sky colours; the horizon colour is also the veil's.
        extinction: Veil coefficient (1/m).
        wet: Whether the ground is wet (darker).
    """

    sun: np.ndarray
    sun_strength: float
    ambient: float
    horizon: np.ndarray
    zenith: np.ndarray
    extinction: float
    wet: bool


def lighting_for(weather: Weather, rng: np.random.Generator, config: CameraConfig) -> Lighting:
    """The sun drawn from ``rng`` and the weather's sky, dimming and veil (see the module doc)."""
    azimuth = rng.uniform(0.0, 2.0 * np.pi)
    elevation = np.deg2rad(rng.uniform(*config.sun_elevation_deg))
    sun = np.array(
        [
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            np.sin(elevation),
        ]
    )
    overcast = float(np.clip(weather.lidar_extinction / 0.01, 0.0, 1.0))
    dim = 1.0 - 0.25 * overcast
    horizon, zenith = (1.0 - overcast) * _SKY_CLEAR + overcast * _SKY_OVERCAST
    extinction = max(weather.lidar_extinction, config.haze)
    # The air between the camera and the sky veils it too (as if the sky were SKY_DEPTH away):
    # fog leaves a uniform grey, rain a flat one, clear air nearly the whole gradient.
    zenith = horizon + (zenith - horizon) * np.exp(-extinction * SKY_DEPTH)
    return Lighting(
        sun=sun,
        sun_strength=0.6 * (1.0 - 0.85 * overcast) * dim,
        ambient=(0.5 + 0.2 * overcast) * dim,
        horizon=horizon * dim,
        zenith=zenith * dim,
        extinction=extinction,
        wet=weather.name == "rain",
    )


def face_colours(
    mesh: TaggedMesh, n_actors: int, rng: np.random.Generator, wet: bool = False
) -> np.ndarray:
    """``(F, 3)`` float32 colour of every face of ``mesh`` (static faces have owner -1).

    Static materials get a per-world tint (+-8 %); each actor draws its car paint, clothes, skin
    and bicycle-frame colours from the palettes (the draws do not depend on the mesh).
    """
    static = STATIC_COLOURS * rng.uniform(0.92, 1.08, size=(len(STATIC_COLOURS), 1))
    static = np.concatenate([static, ROAD_USER_COLOURS])
    if wet:
        static[list(WET_GROUND)] *= 0.78
    picks = rng.integers(0, 1 << 16, size=(n_actors, 4))
    table = np.repeat(static[None].astype(np.float32), n_actors + 1, axis=0)  # last row: static
    paint = picks[:, 0]
    table[:n_actors, Mat.PAINT_DARK] = CAR_DARK[paint % len(CAR_DARK)]
    table[:n_actors, Mat.PAINT_LIGHT] = CAR_LIGHT[paint % len(CAR_LIGHT)]
    table[:n_actors, Mat.CLOTHING] = CLOTHES[picks[:, 1] % len(CLOTHES)]
    table[:n_actors, Mat.CLOTHING_DARK] = table[:n_actors, Mat.CLOTHING]
    table[:n_actors, Mat.SKIN] = SKINS[picks[:, 2] % len(SKINS)]
    table[:n_actors, Mat.BIKE_FRAME] = BIKE_FRAMES[picks[:, 3] % len(BIKE_FRAMES)]
    owner = np.where(mesh.owner >= 0, mesh.owner, n_actors)
    return table[owner, mesh.material.astype(np.int64)]


def camera_rays(calib: Calibration, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The camera centre ``(3,)`` and unit ray directions ``(H * W, 3)`` (row-major, row 0 at the
    top) through the pixel centres of an image of ``size = (W, H)`` whose projection is
    ``calib.P2``, both in the LiDAR frame of ``calib``."""
    width, height = size
    k, p4 = calib.P2[:, :3], calib.P2[:, 3]
    k_inv = np.linalg.inv(k)
    centre_cam = -k_inv @ p4
    to_lidar = calib.cam_to_velo
    m = to_lidar[:3, :3] @ k_inv  # pixel (u, v, 1) -> LiDAR-frame direction
    u = np.arange(width) + 0.5
    v = np.arange(height) + 0.5
    dirs = np.empty((height, width, 3))
    for axis in range(3):  # m @ (u, v, 1), one output axis at a time (no (N, 3) @ (3, 3))
        dirs[..., axis] = m[axis, 0] * u[None, :] + (m[axis, 1] * v + m[axis, 2])[:, None]
    dirs = dirs.reshape(-1, 3)
    dirs /= np.sqrt(np.einsum("ij,ij->i", dirs, dirs))[:, None]
    origin = to_lidar[:3, :3] @ centre_cam + to_lidar[:3, 3]
    return origin, dirs


@dataclass(frozen=True)
class _Rays:
    """:func:`camera_rays` ready for embree: ``origin (3,)``; float32 ``dirs (R, 3)``; float32
    ``zeros (R, 3)`` (the origins once the scene is moved to the camera); ``sky (R,)`` float32 in
    ``[0, 1]``, how far towards the zenith colour the sky is along each ray."""

    origin: np.ndarray
    dirs: np.ndarray
    zeros: np.ndarray
    sky: np.ndarray


_RAYS: dict[tuple, _Rays] = {}
_RAYS_KEPT = 4


def _cached_rays(calib: Calibration, size: tuple[int, int]) -> _Rays:
    """The rays of an image, kept for the last few calibrations (every frame of a generated
    root shares one)."""
    key = (calib.P2.tobytes(), calib.velo_to_cam.tobytes(), tuple(size))
    if key not in _RAYS:
        origin, dirs = camera_rays(calib, size)
        if len(_RAYS) >= _RAYS_KEPT:
            _RAYS.pop(next(iter(_RAYS)))
        dirs32 = np.ascontiguousarray(dirs, dtype=np.float32)
        sky = (np.clip(dirs32[:, 2] * 2.5, 0.0, 1.0) ** 0.8).astype(np.float32)
        _RAYS[key] = _Rays(origin, dirs32, np.zeros_like(dirs32), sky)
    return _RAYS[key]


def first_hits(
    mesh: TaggedMesh, origin: np.ndarray, dirs: np.ndarray, zeros: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """First hits of rays from ``origin (3,)`` along unit float32 ``dirs (R, 3)`` on ``mesh``
    (any frame; embree in float32 with the mesh moved so that ``origin`` is at zero); ``zeros``
    is a float32 ``(R, 3)`` of zeros. Returns the face index ``(R,)`` (-1 = miss) and the
    distance ``(R,)`` float32 (inf = miss)."""
    if len(mesh.faces) == 0:
        return np.full(len(dirs), -1), np.full(len(dirs), np.inf)
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(
        scene=scene,
        vertices=(mesh.vertices - origin).astype(np.float32),
        indices=mesh.faces.astype(np.int32),
    )
    result = scene.run(zeros, dirs, output=1)
    face = np.asarray(result["primID"], dtype=np.int64)
    dist = np.where(face >= 0, result["tfar"], np.float32(np.inf))
    return face, dist


def lit_faces(
    mesh: TaggedMesh, colours: np.ndarray, light: Lighting, origin: np.ndarray
) -> np.ndarray:
    """``(F, 3)`` float32 shaded colour of every face, in ``[0, 255]``, as seen from ``origin``.

    A face is shaded on the side the camera is on (two-sided: its normal is flipped when the
    camera is behind its plane, which for a planar face holds for every ray that hits it):
    ``ambient * (0.75 + 0.25 * n_z) + sun_strength * max(n . sun, 0)`` times its colour.
    """
    tri = mesh.vertices[mesh.faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(normal, axis=1, keepdims=True)
    normal /= np.where(norm > 0, norm, 1.0)
    facing = np.where(np.einsum("ij,ij->i", normal, origin - tri[:, 0]) >= 0, 1.0, -1.0)
    normal *= facing[:, None]
    shade = light.ambient * (0.75 + 0.25 * normal[:, 2]) + light.sun_strength * np.maximum(
        normal @ light.sun, 0.0
    )
    return (np.clip(colours * shade[:, None], 0.0, 1.0) * 255.0).astype(np.float32)


def render_image(
    world: World,
    calib: Calibration,
    image_size: tuple[int, int],
    weather: Weather,
    rng: np.random.Generator,
    config: CameraConfig = CameraConfig(),
) -> np.ndarray:
    """The camera image ``(H, W, 3)`` uint8 of ``world`` at ``t = 0``, for an image of
    ``image_size = (W, H)`` whose calibration is ``calib`` (LiDAR -> camera).

    Raises:
        ValueError: ``config.ray_step`` does not divide ``image_size``.
    """
    width, height = image_size
    step = config.ray_step
    if width % step or height % step:
        raise ValueError(f"ray_step {step} does not divide the {width} x {height} image")
    light = lighting_for(weather, rng, config)
    mesh = TaggedMesh.concatenate([world.static_mesh, world.actor_mesh_at(0.0)])
    colours = face_colours(mesh, len(world.actors), rng, light.wet)
    size = (width // step, height // step)
    rays = _cached_rays(scale_calibration(calib, 1.0 / step), size)
    face, dist = first_hits(mesh, rays.origin, rays.dirs, rays.zeros)
    miss = face < 0
    horizon = (light.horizon * 255.0).astype(np.float32)
    zenith = (light.zenith * 255.0).astype(np.float32)
    # A hit is veiled towards the horizon colour: horizon + (surface - horizon) * keep; a miss
    # shows the sky gradient. Every value is a convex combination of colours in [0, 255].
    lit = np.vstack([lit_faces(mesh, colours, light, rays.origin), horizon]) - horizon
    pixels = lit[np.where(miss, len(lit) - 1, face)]  # the last row (zeros) for a miss
    keep = np.exp(np.float32(-light.extinction) * dist.astype(np.float32, copy=False))
    pixels *= keep[:, None]
    pixels += horizon + np.float32(0.5)
    pixels[miss] = horizon + np.float32(0.5) + np.multiply.outer(rays.sky[miss], zenith - horizon)
    image = pixels.astype(np.uint8).reshape(size[1], size[0], 3)
    if step == 1:
        return image
    upsampled = Image.fromarray(image).resize((width, height), Image.Resampling.BILINEAR)
    return np.asarray(upsampled, dtype=np.uint8).copy()
