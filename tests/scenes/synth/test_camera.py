"""The synthetic camera: deterministic, at the size and pose P2 says, colours by material and
actor, and fog / rain veiling and dimming the image as they degrade the LiDAR."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.geometry.actors import Actor
from scenes.geometry.calib import CAMERA_IN_LIDAR, LIDAR_HEIGHT, vod_lidar_calibration
from scenes.geometry.projection import image_size_at, project_points, scale_calibration
from scenes.synth.camera import (
    CAR_DARK,
    CAR_LIGHT,
    CLOTHES,
    CameraConfig,
    camera_rays,
    face_colours,
    first_hits,
    lighting_for,
    render_image,
)
from scenes.synth.weather import CLEAR, FOG, RAIN
from scenes.synth.world import Mat, TaggedMesh, World, box_part, generate_world

CAM = np.array(CAMERA_IN_LIDAR)
SMALL = CameraConfig(image_scale=0.125, ray_step=1)  # 242 x 152: fast


def _calib(scale: float):
    return scale_calibration(vod_lidar_calibration(), scale)


def _world(static: list[TaggedMesh], cars: list[np.ndarray] = ()) -> World:
    """A world of static parts and box-shaped cars (meshes = their boxes)."""
    actors, meshes = [], []
    for i, box in enumerate(cars):
        actors.append(Actor(i, "Car", box, [0.0, 0.0]))
        half = np.asarray(box[3:6]) / 2
        meshes.append(box_part(-half, half, Mat.PAINT_LIGHT))
    mesh = TaggedMesh.concatenate(static) if static else TaggedMesh.empty()
    return World(0, None, LIDAR_HEIGHT, 0.0, tuple(actors), mesh, tuple(meshes))


def _panel(forward: float, right: float, mat: Mat, width: float = 1.0) -> TaggedMesh:
    """A 1 m tall, ``width`` wide, 2 cm thick panel facing the camera, centred at camera height."""
    x, y, z = CAM + np.array([forward, -right, 0.0])
    return box_part([x, y - width / 2, z - 0.5], [x + 0.02, y + width / 2, z + 0.5], mat)


def _render(world: World, weather=CLEAR, seed: int = 0, config: CameraConfig = SMALL):
    size = image_size_at(config.image_scale)
    calib = _calib(config.image_scale)
    return render_image(world, calib, size, weather, np.random.default_rng(seed), config)


def _pixel(image: np.ndarray, point: np.ndarray, scale: float) -> np.ndarray:
    """The colour (float) at the projection of a LiDAR-frame point."""
    h, w = image.shape[:2]
    uv = project_points(point[None], _calib(scale), (w, h)).uv[0]
    return image[int(uv[1]), int(uv[0])].astype(float)


def test_render_is_deterministic_and_the_seed_matters():
    world = generate_world(np.random.default_rng(0), 0)
    a, b = _render(world, seed=1), _render(world, seed=1)
    assert a.dtype == np.uint8 and a.shape == (152, 242, 3)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, _render(world, seed=2))  # another sun, other tints and paints


@pytest.mark.parametrize("scale, step", [(0.25, 2), (0.125, 1)])
def test_image_size_and_geometry_follow_p2(scale, step):
    # One car 12 m ahead, 1.5 m right; no ground: everything else is sky.
    box = np.array([*(CAM + np.array([12.0, -1.5, 0.0])), 4.0, 1.8, 1.5, 0.3])
    config = CameraConfig(image_scale=scale, ray_step=step)
    image = _render(_world([], [box]), config=config)
    sky = _render(_world([]), config=config)
    width, height = image_size_at(scale)
    assert image.shape == (height, width, 3)
    car = np.abs(image.astype(int) - sky.astype(int)).max(axis=2) > 12
    rows, cols = np.nonzero(car)
    # The car's pixels span the projection of its corners (P2 scaled to this size) to a pixel
    # or two (one ray per step x step pixels, upsampled).
    from scenes.geometry.boxes import box_corners

    uv = project_points(box_corners(box)[0], _calib(scale), (width, height)).uv
    tol = 1.0 + step
    assert abs(cols.min() - uv[:, 0].min()) <= tol and abs(cols.max() + 1 - uv[:, 0].max()) <= tol
    assert abs(rows.min() - uv[:, 1].min()) <= tol and abs(rows.max() + 1 - uv[:, 1].max()) <= tol
    with pytest.raises(ValueError, match="ray_step"):
        render_image(_world([]), _calib(1.0), (1936, 1215), CLEAR, np.random.default_rng(0))


def test_rays_leave_the_camera_through_their_pixel_centres():
    calib = _calib(0.125)
    origin, dirs = camera_rays(calib, (242, 152))
    np.testing.assert_allclose(origin, CAM, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0)
    uv = project_points(origin + 10.0 * dirs[[0, 241, 242 * 151 + 7]], calib, (242, 152)).uv
    np.testing.assert_allclose(uv, [[0.5, 0.5], [241.5, 0.5], [7.5, 151.5]], atol=1e-6)
    # Distances are along the unit rays: a panel 10 m ahead is hit at 10 m on the axis.
    axis = np.array([[1.0, 0.0, 0.0]], dtype=np.float32)
    face, dist = first_hits(_panel(10.0, 0.0, Mat.BRICK), CAM, axis, np.zeros_like(axis))
    assert face[0] >= 0 and dist[0] == pytest.approx(10.0, abs=1e-4)


def test_colours_differ_by_material():
    mats = [Mat.MARKING, Mat.BIKE_PATH, Mat.GRASS, Mat.BRICK, Mat.GLASS_FACADE, Mat.SIGN]
    mats += [Mat.FOLIAGE, Mat.ASPHALT, Mat.CONCRETE]
    offsets = (np.arange(len(mats)) - (len(mats) - 1) / 2) * 1.2
    world = _world([_panel(15.0, r, m) for r, m in zip(offsets, mats, strict=True)])
    image = _render(world, config=CameraConfig(image_scale=0.25, ray_step=1))
    colours = [_pixel(image, CAM + np.array([15.0, -r, 0.0]), 0.25) for r in offsets]
    for i in range(len(mats)):
        for j in range(i):
            assert np.abs(colours[i] - colours[j]).max() > 12, (mats[i], mats[j])


def test_actors_draw_colours_from_their_palettes():
    n = 40
    mesh = TaggedMesh.concatenate(
        [
            box_part([0, 0, 0], [1, 1, 1], mat).with_owner(i)
            for i in range(n)
            for mat in (Mat.PAINT_DARK, Mat.PAINT_LIGHT, Mat.CLOTHING)
        ]
    )
    colours = face_colours(mesh, n, np.random.default_rng(0)).reshape(n, 3, 12, 3)[:, :, 0]
    for k, palette in enumerate((CAR_DARK, CAR_LIGHT, CLOTHES)):
        seen = {tuple(c) for c in colours[:, k]}
        assert seen <= {tuple(c) for c in palette} and len(seen) >= 3


def test_fog_veils_far_surfaces_and_rain_dims():
    near, far = CAM + np.array([5.0, 1.0, 0.0]), CAM + np.array([40.0, -3.0, 0.0])
    world = _world([_panel(5.0, -1.0, Mat.SIGN), _panel(40.0, 3.0, Mat.SIGN, width=3.0)])
    config = CameraConfig(image_scale=0.25, ray_step=1)
    clear, fog = _render(world, CLEAR, config=config), _render(world, FOG, config=config)
    veil = lighting_for(FOG, np.random.default_rng(0), config).horizon * 255
    # Fog (0.12 /m): 40 m away keeps exp(-4.8) < 1 % of the surface: the veil's colour; 5 m away
    # keeps 55 %. In clear air both are far from the sky.
    assert np.abs(_pixel(fog, far, 0.25) - veil).max() < 3
    assert np.abs(_pixel(fog, near, 0.25) - veil).max() > 30
    clear_sky = lighting_for(CLEAR, np.random.default_rng(0), config).horizon * 255
    assert np.abs(_pixel(clear, far, 0.25) - clear_sky).max() > 60
    # A whole street: fog flattens the contrast, rain darkens it.
    street = generate_world(np.random.default_rng(3), 3)
    images = {w.name: _render(street, w).astype(float) for w in (CLEAR, RAIN, FOG)}
    assert images["fog"].std() < 0.6 * images["clear"].std()
    assert images["rain"].mean() < 0.85 * images["clear"].mean()


def test_bad_camera_settings_are_refused():
    for kwargs, match in (
        ({"image_scale": 0.3}, "scale"),
        ({"ray_step": 3}, "ray_step"),
        ({"jpeg_quality": 0}, "jpeg_quality"),
        ({"sun_elevation_deg": (50.0, 10.0)}, "sun_elevation"),
    ):
        with pytest.raises(ValueError, match=match):
            CameraConfig(**kwargs)
    assert CameraConfig(image_scale=0.5).image_size == (968, 608)
