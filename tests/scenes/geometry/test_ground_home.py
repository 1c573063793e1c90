"""Ground estimation has one home, ``scenes/geometry/ground.py``: its functions on a synthetic
frame (estimates against the labelled boxes' bottoms), and no module elsewhere that takes a
percentile or median of point heights itself."""

from __future__ import annotations

import ast

import numpy as np
import pytest

from scenes.geometry.ground import (
    LOCAL_MIN_POINTS,
    ground_around,
    ground_under_boxes,
    sensor_ground_height,
)
from tests.paths import REPO as ROOT

SCANNED = ("annotate", "app", "model", "scenes", "bench", "tools", "launch.py")
HOME = ROOT / "scenes" / "geometry"
STATISTICS = {
    "percentile",
    "quantile",
    "median",
    "nanpercentile",
    "nanquantile",
    "nanmedian",
}
CLOUDS = ("p", "pts", "points", "lidar", "xyz", "cloud")
"""Names of a point cloud whose ``[:, 2]`` column is its heights."""


@pytest.fixture(scope="module")
def frame():
    """Two synthetic frames' LiDAR points, labelled boxes within 40 m and their classes."""
    from scenes.geometry.calib import sensor_to_lidar
    from scenes.synth.frame import SynthSettings, synthesize

    settings = SynthSettings(seed=7, camera=None)
    r2l = sensor_to_lidar(*settings.calibrations())
    out = []
    for index in (0, 1):
        f = synthesize(settings, index, r2l)
        near = [a for a in f.world.actors if np.hypot(*a.box[:2]) < 40.0]
        boxes = np.array([a.box for a in near]).reshape(-1, 7)
        out.append((f.lidar.points, boxes, [a.cls for a in near]))
    return out


def test_local_ground_meets_the_boxes_bottoms(frame):
    errors = []
    for points, boxes, classes in frame:
        bottoms = boxes[:, 2] - boxes[:, 5] / 2
        got = ground_under_boxes(points, boxes)
        errors.extend((got - bottoms)[np.isfinite(got)])
        # Around a point of the road ahead: the road the cars stand on.
        cars = bottoms[[c == "Car" for c in classes]]
        for centre in ((6.0, 0.0), (15.0, 0.0)):
            assert ground_around(points, centre, 2.0) == pytest.approx(np.median(cars), abs=0.03)
    errors = np.abs(np.array(errors))
    assert len(errors) >= 10
    assert np.median(errors) < 0.02 and np.mean(errors) < 0.08


def test_sensor_ground_height_meets_the_boxes_bottoms(frame):
    for points, boxes, classes in frame:
        cars = boxes[[c == "Car" for c in classes]]  # on the road (others may stand on a kerb)
        road = np.median(cars[:, 2] - cars[:, 5] / 2)
        assert sensor_ground_height(points, 1.7) == pytest.approx(road, abs=0.05)
    assert sensor_ground_height(np.zeros((0, 4)), 1.9) == -1.9  # no plane: the reference
    assert sensor_ground_height(np.zeros((5, 4)), 2.0) == -2.0


def test_local_ground_rules():
    rng = np.random.default_rng(3)
    ground = np.c_[rng.uniform(-10, 10, (4000, 2)), rng.normal(-1.5, 0.01, 4000)]
    box = np.array([0.0, 0.0, -0.7, 4.0, 2.0, 1.6, 0.4])
    # A car's roof inside the footprint, 0.3 m above the ground: left out of the ring's estimate,
    # counted with the footprint.
    roof = np.c_[rng.uniform(-0.9, 0.9, (8000, 2)), np.full(8000, -1.2)]
    inside = np.r_[ground[np.abs(ground[:, :2]).max(1) > 3.0], roof]
    assert ground_under_boxes(inside, box)[0] == pytest.approx(-1.5, abs=0.03)
    assert ground_under_boxes(inside, box, with_footprint=True)[0] > -1.3
    far = box.copy()
    far[0] = 60.0
    assert np.isnan(ground_under_boxes(ground, far)[0])  # no ring points: no estimate
    few = ground[: LOCAL_MIN_POINTS - 1]
    assert np.isnan(ground_around(few, (0.0, 0.0), 100.0))
    assert ground_under_boxes(np.zeros((0, 4)), np.zeros((0, 7))).shape == (0,)


def _statistic_calls(tree: ast.AST) -> list[tuple[int, str]]:
    """``(line, function)`` of each percentile / quantile / median call that takes point heights:
    inside a function whose name says ground, or with a height argument (a name ``z``, ``*_z``,
    ``z_*`` or a ``[..., 2]`` column)."""
    found = []

    def visit(node: ast.AST, function: str) -> None:
        for child in ast.iter_child_nodes(node):
            name = function
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                name = child.name
            if (
                isinstance(child, ast.Call)
                and isinstance(child.func, ast.Attribute)
                and child.func.attr in STATISTICS
            ):
                text = " ".join(ast.unparse(a) for a in child.args)
                heights = any(
                    isinstance(n, ast.Name) and (n.id == "z" or "_z" in n.id or n.id[:2] == "z_")
                    for a in child.args
                    for n in ast.walk(a)
                ) or any(f"{cloud}[:, 2]" in text for cloud in CLOUDS)
                if "ground" in function.lower() or heights:
                    found.append((child.lineno, function))
            visit(child, name)

    visit(tree, "")
    return found


def test_the_checker_finds_the_former_estimates():
    """The four estimates this test keeps out: each one is found (the check can fail)."""
    former = {
        "app": (
            "def estimate_ground_z(lidar):\n"
            "    near = lidar[(rng > 3.0) & (rng < 30.0), 2]\n"
            "    return float(np.clip(np.percentile(near, 10), -4.0, 0.5))\n"
        ),
        "pseudo": "def ground_heights(b, l):\n    out[k] = float(np.median(z[: len(z) // 3]))\n",
        "fitting": "def fit_box(p):\n    g = float(np.percentile(z[around], cfg.ground_percentile))\n",
        "column": "def level(p):\n    return np.quantile(p[:, 2], 0.05)\n",
    }
    for what, source in former.items():
        assert _statistic_calls(ast.parse(source)), what
    assert not _statistic_calls(ast.parse("def speed(v):\n    return np.median(v[:, 5])\n"))


def test_no_ground_height_is_computed_outside_its_home():
    offenders = []
    for name in SCANNED:
        path = ROOT / name
        files = [path] if path.suffix == ".py" else sorted(path.rglob("*.py"))
        for file in files:
            if HOME in file.parents:
                continue
            tree = ast.parse(file.read_text(encoding="utf-8"), filename=str(file))
            offenders += [f"{file.relative_to(ROOT)}:{n} ({f})" for n, f in _statistic_calls(tree)]
    assert not offenders, (
        "ground heights computed outside scenes/geometry/ground.py (use its functions): "
        + ", ".join(offenders)
    )


def test_the_former_estimators_use_the_home():
    for module in ("app/serving/navigation.py", "model/adapt/pseudo.py", "annotate/fitting.py"):
        assert "scenes.geometry.ground import" in (ROOT / module).read_text(encoding="utf-8")
