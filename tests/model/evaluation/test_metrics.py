"""The official VoD metric (model.evaluation.metrics) on hand-made cases with hand-computed expectations.

Reminders used below (see model/evaluation/metrics.py): with N <= 40 valid objects and k true positives that
all come before any false positive, the k score thresholds fill precision slots 0..k-1 with 1, so
AP R11 = ceil(k / 4) / 11 x 100 (slots 0, 4, ..., 40) and AP R40 = (k - 1) / 40 x 100 (slots 1..40).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from model.evaluation.metrics import (
    MIN_HEIGHT_PX,
    camera_bev_iou,
    camera_iou3d,
    evaluate_frames,
    image_iou,
    score_thresholds,
)
from scenes.frame.kitti import ObjectLabel

CAR_HWL = (1.5, 1.8, 4.0)


def obj(
    x: float,
    z: float,
    ry: float = 0.0,
    *,
    name: str = "Car",
    hwl: tuple[float, float, float] = CAR_HWL,
    y: float = 1.5,
    left: float = 500.0,
    height_px: float = 100.0,
    alpha: float = 0.0,
    score: float | None = None,
) -> ObjectLabel:
    """A label: camera-frame bottom centre (x, y, z), a 2D box ``left..left+80`` x ``400..400+h``."""
    return ObjectLabel(
        name=name,
        truncated=0.0 if score is None else -1.0,
        occluded=0 if score is None else -1,
        alpha=alpha,
        bbox=(left, 400.0, left + 80.0, 400.0 + height_px),
        dimensions_hwl=hwl,
        location=(x, y, z),
        rotation_y=ry,
        score=score,
    )


def det_of(gt: ObjectLabel, score: float, **changes) -> ObjectLabel:
    """A detection copying ``gt`` with ``rotation_y + 0.01`` (the spec's perfect detector)."""
    d = replace(gt, truncated=-1.0, occluded=-1, rotation_y=gt.rotation_y + 0.01, score=score)
    return replace(d, **changes)


def one_car_per_frame(n: int, x: float = 0.0, start_z: float = 6.0):
    """``n`` frames, each with one car ahead (inside the corridor while z <= 25)."""
    gt = {f"{i:05d}": [obj(x, start_z + (i % 10))] for i in range(n)}
    return gt


def r11(k: int) -> float:
    return math.ceil(k / 4) / 11 * 100


def r40(k: int) -> float:
    return max(k - 1, 0) / 40 * 100


# ---------------------------------------------------------------------------------------------
# Overlaps


def test_identical_boxes_have_iou_one():
    boxes = np.array(
        [
            [1.0, 1.5, 20.0, 4.0, 1.5, 1.8, 0.3],
            [-3.0, 1.2, 7.5, 0.8, 1.7, 0.6, -2.9],
            [2.0, 1.6, 40.0, 1.8, 1.7, 0.7, 1.5707963267948966],
        ]
    )
    np.testing.assert_allclose(np.diag(camera_bev_iou(boxes, boxes)), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.diag(camera_iou3d(boxes, boxes)), 1.0, atol=1e-12)


def test_bev_length_axis_is_cos_ry_minus_sin_ry():
    # A long thin box at the origin; a tiny probe box where its front end lies if the length axis
    # is (cos ry, -sin ry) in the camera x-z plane (the devkit's and KITTI's convention).
    ry = 0.7
    big = np.array([[0.0, 1.0, 10.0, 6.0, 1.0, 0.4, ry]])
    front = np.array([2.8 * math.cos(ry), 1.0, 10.0 - 2.8 * math.sin(ry)])
    mirrored = np.array([2.8 * math.cos(ry), 1.0, 10.0 + 2.8 * math.sin(ry)])
    probe = np.array([[*front, 0.1, 1.0, 0.1, 0.0]])
    probe_mirrored = np.array([[*mirrored, 0.1, 1.0, 0.1, 0.0]])
    assert camera_bev_iou(probe, big)[0, 0] > 0
    assert camera_bev_iou(probe_mirrored, big)[0, 0] == 0


def test_3d_vertical_overlap_spans_y_minus_h_to_y():
    # Same footprint; b's bottom is h/2 higher (camera y points down): overlap h/2 of height h.
    a = np.array([[0.0, 1.5, 10.0, 4.0, 1.5, 1.8, 0.0]])
    b = a.copy()
    b[0, 1] -= 0.75
    assert camera_bev_iou(a, b)[0, 0] == pytest.approx(1.0)
    assert camera_iou3d(a, b)[0, 0] == pytest.approx(0.75 / (3.0 - 0.75))


def test_shift_along_length_gives_hand_computed_iou():
    a = np.array([[0.0, 1.5, 10.0, 4.0, 1.5, 1.8, 0.0]])  # ry = 0: length along x
    b = a.copy()
    b[0, 0] += 1.0
    assert camera_bev_iou(a, b)[0, 0] == pytest.approx(3.0 / 5.0)
    assert camera_iou3d(a, b)[0, 0] == pytest.approx(3.0 / 5.0)


def test_image_iou():
    a = np.array([[0.0, 0.0, 100.0, 100.0]])
    b = np.array([[50.0, 0.0, 150.0, 100.0], [200.0, 0.0, 300.0, 50.0]])
    np.testing.assert_allclose(image_iou(a, b), [[5000 / 15000, 0.0]])


# ---------------------------------------------------------------------------------------------
# Thresholds


def test_score_thresholds_keep_every_tp_when_few():
    assert score_thresholds([0.3, 0.9, 0.5], num_gt=10).tolist() == [0.9, 0.5, 0.3]


def test_score_thresholds_are_spaced_in_recall():
    # 80 true positives of 80: score i (descending) is kept when k/40 <= (2i + 3) / 160, i.e.
    # i = 0 and then i = 2k - 1 for k = 1..40.
    scores = 1.0 - np.arange(80) / 100.0
    kept = score_thresholds(scores, num_gt=80)
    expected = [scores[0]] + [scores[2 * k - 1] for k in range(1, 41)]
    np.testing.assert_allclose(kept, expected)


# ---------------------------------------------------------------------------------------------
# Whole evaluation


@pytest.mark.parametrize("n", [1, 6, 16, 33])
def test_perfect_detector(n):
    gt = one_car_per_frame(n)
    rng = np.random.default_rng(n)
    dt = {f: [det_of(g[0], float(rng.uniform(0.5, 1.0)))] for f, g in gt.items()}
    res = evaluate_frames(gt, dt)
    for area in (res.entire_area, res.roi):
        car = area["Car"]
        assert car.num_gt == n
        for value in (car.ap_3d, car.ap_bev, car.aos, car.ap_2d):
            assert value.r11 == pytest.approx(r11(n))
            assert value.r40 == pytest.approx(r40(n))
        assert area["Pedestrian"].ap_3d.r11 == 0.0  # no ground truth -> 0, as the devkit
        assert area.map_3d == pytest.approx(r11(n) / 3)


def test_perfect_detector_identical_boxes_exact_overlaps():
    gt = one_car_per_frame(6)
    dt = {f: [replace(g[0], score=0.9)] for f, g in gt.items()}
    for offsets in (True, False):
        res = evaluate_frames(gt, dt, devkit_offsets=offsets)
        assert res.entire_area["Car"].ap_3d.r11 == pytest.approx(r11(6))


def test_half_found_of_many_uses_recall_spacing():
    # 80 cars, 40 found perfectly: thresholds at TP indices 0, 1, 3, ..., 39 (21 of them), so
    # slots 0..20 hold precision 1: R11 = 6/11, R40 = 20/40.
    gt = one_car_per_frame(80)
    dt = {f: [det_of(g[0], 1.0 - i / 100)] for i, (f, g) in enumerate(gt.items()) if i < 40}
    res = evaluate_frames(gt, dt)
    car = res.entire_area["Car"]
    assert car.num_gt == 80
    assert car.ap_3d.r11 == pytest.approx(6 / 11 * 100)
    assert car.ap_3d.r40 == pytest.approx(20 / 40 * 100)


def test_shifted_box_below_threshold_is_a_false_positive():
    gt = {"00000": [obj(0.0, 10.0)]}
    # ry = 0: the length (4 m) runs along x; a 2 m shift leaves IoU 2/6 < 0.5.
    far = {"00000": [det_of(gt["00000"][0], 0.9, location=(2.0, 1.5, 10.0))]}
    near = {"00000": [det_of(gt["00000"][0], 0.9, location=(0.5, 1.5, 10.0))]}
    res = evaluate_frames(gt, far)
    assert res.entire_area["Car"].ap_3d.r11 == 0.0
    assert res.entire_area["Car"].ap_bev.r11 == 0.0
    assert res.entire_area["Car"].ap_2d.r11 == pytest.approx(r11(1))  # the 2D box still matches
    assert evaluate_frames(gt, near).entire_area["Car"].ap_3d.r11 == pytest.approx(r11(1))


def test_overlap_must_be_strictly_greater_than_threshold():
    # Length 3 along x, shift 1: BEV and 3D IoU exactly (3 - 1) / (3 + 1) = 0.5 = the Car minimum.
    gt = {"00000": [obj(0.0, 10.0, hwl=(1.0, 1.0, 3.0))]}
    dt = {"00000": [replace(gt["00000"][0], location=(1.0, 1.5, 10.0), score=0.9)]}
    car = evaluate_frames(gt, dt, devkit_offsets=False).entire_area["Car"]
    assert camera_iou3d(
        np.array([[0.0, 1.5, 10.0, 3.0, 1.0, 1.0, 0.0]]),
        np.array([[1.0, 1.5, 10.0, 3.0, 1.0, 1.0, 0.0]]),
    )[0, 0] == pytest.approx(0.5, abs=1e-15)
    assert car.ap_3d.r11 == 0.0
    assert car.ap_bev.r11 == 0.0
    # With a second, well-detected car (score 0.5) the IoU-0.5 detection (score 0.9) is a false
    # positive at the only threshold (0.5): precision 1/2, in the PR pass as well.
    second = obj(0.0, 20.0, hwl=(1.0, 1.0, 3.0), left=900)
    gt["00000"].append(second)
    dt["00000"].append(replace(second, score=0.5))
    car = evaluate_frames(gt, dt, devkit_offsets=False).entire_area["Car"]
    assert car.ap_3d.r11 == pytest.approx(0.5 / 11 * 100)


def test_corridor_filtering():
    # Inside the corridor: -4 <= x <= 4 and z <= 25 (inclusive). Outside: x = 5, x = -4.5, z = 26.
    inside = [obj(0.0, 10.0, left=100), obj(4.0, 12.0, left=300), obj(-4.0, 25.0, left=500)]
    outside = [obj(5.0, 10.0, left=700), obj(-4.5, 15.0, left=900), obj(0.0, 26.0, left=1100)]
    gt = {"00000": inside + outside}
    # Perfect detections; the ones outside score highest, so they would be false positives ahead
    # of every true positive if the corridor counted them.
    dt = {
        "00000": [det_of(g, 0.5) for g in inside]
        + [det_of(g, 0.9) for g in outside]
        + [det_of(obj(6.0, 30.0, left=1300), 0.95)]  # a false positive outside: ignored in roi
    }
    res = evaluate_frames(gt, dt)
    assert res.entire_area["Car"].num_gt == 6
    assert res.roi["Car"].num_gt == 3
    assert res.roi["Car"].ap_3d.r11 == pytest.approx(r11(3))
    assert res.roi["Car"].ap_3d.r40 == pytest.approx(r40(3))
    # Entire area: thresholds 0.9, 0.9, 0.9, 0.5, 0.5, 0.5 (six true positives); the false positive
    # (0.95) is above all of them: precision 3/4 at 0.9 and 6/7 at 0.5, tail maximum 6/7 in
    # slots 0..5, so R11 = 2 x 6/7 / 11.
    assert res.entire_area["Car"].ap_3d.r11 == pytest.approx(2 * (6 / 7) / 11 * 100)


def test_two_d_height_filter():
    # Ground truth of height exactly 40 px is ignored (<= 40); 41 px counts.
    gt = {
        "00000": [obj(0.0, 10.0, height_px=MIN_HEIGHT_PX, left=100)],
        "00001": [obj(0.0, 10.0, height_px=41.0, left=100)],
    }
    dt = {f: [det_of(g[0], 0.5 + i / 10)] for i, (f, g) in enumerate(gt.items())}
    car = evaluate_frames(gt, dt).entire_area["Car"]
    assert car.num_gt == 1
    assert car.ap_3d.r11 == pytest.approx(r11(1))  # the detection on the ignored GT is no FP
    assert car.ap_3d.r40 == 0.0

    # A detection under 40 px is ignored even when it hits nothing and scores highest...
    gt = {"00000": [obj(0.0, 10.0, left=100)]}
    small_fp = det_of(obj(0.0, 40.0, left=900, height_px=39.9), 0.9)
    dt = {"00000": [det_of(gt["00000"][0], 0.5), small_fp]}
    assert evaluate_frames(gt, dt).entire_area["Car"].ap_3d.r11 == pytest.approx(r11(1))
    # ...while one of exactly 40 px counts: precision 1/2 at the only threshold.
    dt["00000"][1] = det_of(obj(0.0, 40.0, left=900, height_px=40.0), 0.9)
    assert evaluate_frames(gt, dt).entire_area["Car"].ap_3d.r11 == pytest.approx(0.5 / 11 * 100)


def test_aos_with_flipped_heading():
    gt = one_car_per_frame(6)
    for f, labels in gt.items():
        gt[f] = [replace(labels[0], rotation_y=0.4, alpha=0.3)]
    flipped = {
        f: [det_of(g[0], 0.8, rotation_y=0.4 + math.pi, alpha=0.3 + math.pi)] for f, g in gt.items()
    }
    car = evaluate_frames(gt, flipped).entire_area["Car"]
    assert car.ap_3d.r11 == pytest.approx(r11(6))  # a box turned by pi is the same box
    assert car.ap_bev.r11 == pytest.approx(r11(6))
    assert car.aos.r11 == pytest.approx(0.0, abs=1e-9)
    # A quarter turn of alpha halves the similarity: (1 + cos(pi/2)) / 2 = 1/2.
    quarter = {f: [det_of(g[0], 0.8, alpha=0.3 + math.pi / 2)] for f, g in gt.items()}
    car = evaluate_frames(gt, quarter).entire_area["Car"]
    assert car.aos.r11 == pytest.approx(r11(6) / 2)
    assert car.aos.r40 == pytest.approx(r40(6) / 2)


def test_score_order_of_false_positive():
    gt = {"00000": [obj(0.0, 10.0, left=100), obj(3.0, 20.0, left=300)]}
    tp1, tp2 = det_of(gt["00000"][0], 0.9), det_of(gt["00000"][1], 0.7)
    fp = obj(-3.0, 40.0, left=800)
    # TP 0.9, FP 0.8, TP 0.7: thresholds 0.9 (precision 1) and 0.7 (precision 2/3).
    dt = {"00000": [tp1, det_of(fp, 0.8), tp2]}
    car = evaluate_frames(gt, dt).entire_area["Car"]
    assert car.ap_3d.r11 == pytest.approx(1 / 11 * 100)
    assert car.ap_3d.r40 == pytest.approx((2 / 3) / 40 * 100)
    # FP 0.95 first: precision 1/2 then 2/3; the tail maximum makes slot 0 = 2/3 too.
    dt = {"00000": [tp1, det_of(fp, 0.95), tp2]}
    car = evaluate_frames(gt, dt).entire_area["Car"]
    assert car.ap_3d.r11 == pytest.approx((2 / 3) / 11 * 100)
    assert car.ap_3d.r40 == pytest.approx((2 / 3) / 40 * 100)
    # FP below every TP score: never counted at any threshold.
    dt = {"00000": [tp1, det_of(fp, 0.1), tp2]}
    assert evaluate_frames(gt, dt).entire_area["Car"].ap_3d.r40 == pytest.approx(1 / 40 * 100)


def test_class_names_are_case_insensitive_and_other_classes_do_not_match():
    gt = {"00000": [obj(0.0, 10.0, name="car")]}
    assert evaluate_frames(gt, {"00000": [det_of(gt["00000"][0], 0.9, name="CAR")]}).entire_area[
        "Car"
    ].ap_3d.r11 == pytest.approx(r11(1))
    wrong = evaluate_frames(gt, {"00000": [det_of(gt["00000"][0], 0.9, name="Cyclist")]})
    assert wrong.entire_area["Car"].ap_3d.r11 == 0.0
    assert wrong.entire_area["Cyclist"].ap_3d.r11 == 0.0  # no Cyclist ground truth


def test_pedestrian_threshold_is_a_quarter():
    ped = obj(0.0, 10.0, name="Pedestrian", hwl=(1.75, 0.6, 0.8))
    # Shift 0.45 m along the 0.8 m length: IoU 0.35 / 1.25 = 0.28 > 0.25 (it would fail for Car).
    dt = {"00000": [det_of(ped, 0.9, location=(0.45, 1.5, 10.0))]}
    res = evaluate_frames({"00000": [ped]}, dt)
    assert res.entire_area["Pedestrian"].ap_3d.r11 == pytest.approx(r11(1))


def test_dont_care_region_hides_false_positives_in_the_2d_pass_only():
    gt = {"00000": [obj(0.0, 10.0, left=100), obj(0.0, 30.0, name="DontCare", left=900)]}
    fp_on_dont_care = det_of(obj(3.0, 45.0, left=900), 0.9)
    dt = {"00000": [det_of(gt["00000"][0], 0.5), fp_on_dont_care]}
    car = evaluate_frames(gt, dt).entire_area["Car"]
    assert car.aos.r11 == pytest.approx(r11(1))  # AOS comes from the 2D pass
    assert car.ap_3d.r11 == pytest.approx(0.5 / 11 * 100)


def test_missing_frames_count_as_misses_and_extra_frames_fail():
    gt = one_car_per_frame(4)
    dt = {"00000": [det_of(gt["00000"][0], 0.9)]}
    assert evaluate_frames(gt, dt).entire_area["Car"].num_gt == 4
    with pytest.raises(ValueError, match="99999"):
        evaluate_frames(gt, {"99999": []})


def test_result_dict_keys():
    gt = one_car_per_frame(2)
    d = evaluate_frames(gt, {}).to_dict()
    assert set(d) == {"entire_area", "roi"}
    expected = {
        f"{c}_{m}_all{s}"
        for c in ("Car", "Pedestrian", "Cyclist")
        for m in ("3d", "bev", "aos")
        for s in ("", "_R40")
    } | {f"{m}{s}" for m in ("mAP_3d", "mAP_bev", "mAOS") for s in ("", "_R40")}
    assert set(d["entire_area"]) == expected
    assert set(d["roi"]) == expected
    assert all(v == 0.0 for v in d["roi"].values())  # no detections at all
