"""The Talk2Car metrics (model.evaluation.talk2car.metrics) on hand-made cases: a perfect box, a
shifted box, IoU exactly at a threshold, empty predictions, the 2D AP50 and top-1."""

from __future__ import annotations

import numpy as np
import pytest

from model.evaluation.talk2car.metrics import (
    MSSG_THRESHOLDS,
    CommandBoxes,
    grounding_ap,
    interpolated_ap,
    iou_2d,
    table_ii,
    talk2car_ap,
    top1_distance,
    top1_hits,
)
from model.evaluation.talk2car.report import subset_of
from scenes.geometry.boxes import bev_iou

CAR = np.array([10.0, 0.0, 0.0, 4.0, 2.0, 1.5, 0.0])


def command(boxes, scores, referent=CAR, cls="Car"):
    return CommandBoxes.make(np.asarray(boxes).reshape(-1, 7), scores, referent, cls)


def test_a_perfect_box_scores_100_everywhere():
    figures = table_ii([command([CAR], [0.9])])
    assert figures == pytest.approx({k: 100.0 for k in figures})
    assert top1_hits([command([CAR], [0.9])]).tolist() == [True]


def test_a_shifted_box_passes_ap_b_but_not_ap_a():
    # shifted 1 m along x: BEV IoU = (3 * 2) / (2 * 8 - 6) = 0.6
    shifted = CAR + np.array([1.0, 0, 0, 0, 0, 0, 0])
    assert bev_iou(shifted[None], CAR[None])[0, 0] == pytest.approx(0.6)
    figures = table_ii([command([shifted], [0.8])])
    assert figures["BEV AP_A"] == 0.0 and figures["3D AP_A"] == 0.0
    assert figures["BEV AP_B"] == 100.0 and figures["3D AP_B"] == 100.0
    assert top1_hits([command([shifted], [0.8])]).tolist() == [True]  # 1.0 m: the limit for a car
    further = CAR + np.array([1.01, 0, 0, 0, 0, 0, 0])
    assert top1_hits([command([further], [0.8])]).tolist() == [False]


def test_iou_exactly_at_the_threshold_does_not_count():
    # BEV IoU exactly 0.5: shifted by 4/3 m along x -> overlap 8/3 * 2 / (16 - 16/3) = 0.5
    shifted = CAR + np.array([4.0 / 3.0, 0, 0, 0, 0, 0, 0])
    assert bev_iou(shifted[None], CAR[None])[0, 0] == pytest.approx(0.5)
    at = {"Car": float(bev_iou(shifted[None], CAR[None])[0, 0])}
    assert grounding_ap([command([shifted], [1.0])], bev_iou, at) == 0.0
    below = {"Car": at["Car"] - 1e-9}
    assert grounding_ap([command([shifted], [1.0])], bev_iou, below) == 100.0
    assert MSSG_THRESHOLDS["AP_B"]["Car"] == 0.5


def test_empty_predictions_score_zero():
    empty = command(np.zeros((0, 7)), [])
    assert table_ii([empty]) == {k: 0.0 for k in table_ii([empty])}
    assert top1_hits([empty]).tolist() == [False]
    assert table_ii([]) == {k: 0.0 for k in table_ii([])}
    assert talk2car_ap([None], [[0, 0, 10, 10]]) == 0.0
    assert talk2car_ap([], []) == 0.0


def test_ranking_across_commands_gives_partial_ap():
    wrong = CAR + np.array([0, 10.0, 0, 0, 0, 0, 0])
    # the high-scored box is wrong, the low-scored one right: precision 1/2 at recall 1/2,
    # and the second command's right box comes last: precision 2/3 at recall 1
    cmds = [command([wrong, CAR], [0.9, 0.1]), command([CAR], [0.5])]
    ap = grounding_ap(cmds, bev_iou, {"Car": 0.5})
    assert ap == pytest.approx(100 * (20 * 2 / 3 + 20 * 2 / 3) / 40)
    assert interpolated_ap(np.array([True, True]), np.array([0.5, 0.4]), 4) == pytest.approx(50.0)


def test_talk2car_ap50_is_strictly_above_one_half():
    assert iou_2d([0, 0, 10, 10], [0, 0, 10, 10]) == pytest.approx(1.0)
    # IoU exactly 0.5: [0, 0, 10, 10] against [0, 0, 10, 5]
    assert iou_2d([0, 0, 10, 10], [0, 0, 10, 5]) == pytest.approx(0.5)
    assert talk2car_ap([[0, 0, 10, 5]], [[0, 0, 10, 10]]) == 0.0
    assert talk2car_ap([[0, 0, 10, 5.01]], [[0, 0, 10, 10]]) == 100.0
    assert talk2car_ap([[0, 0, 10, 10], [50, 50, 10, 10]], [[0, 0, 10, 10]] * 2) == 50.0


def test_pedestrian_thresholds_and_top1_distance():
    ped = np.array([8.0, 2.0, 0.0, 0.8, 0.8, 1.8, 0.0])
    off = ped + np.array([0.51, 0, 0, 0, 0, 0, 0])
    assert top1_hits([command([off], [1.0], ped, "Pedestrian")]).tolist() == [False]
    assert top1_hits([command([ped], [1.0], ped, "Pedestrian")]).tolist() == [True]


def test_other_classes_are_scored_as_the_class_they_are_like():
    """A nuScenes-class model's referents: a truck as a car (1.0 m, AP_A 0.7), a traffic cone
    and a bicycle as a pedestrian or cyclist (0.5 m, AP_A 0.5); an unknown class is refused."""
    truck = np.array([12.0, 0.0, 0.0, 7.0, 2.5, 2.8, 0.0])
    off = truck + np.array([0.9, 0, 0, 0, 0, 0, 0])  # BEV IoU 6.1 / 7.9 = 0.77
    assert top1_hits([command([off], [1.0], truck, "Truck")]).tolist() == [True]
    assert table_ii([command([off], [1.0], truck, "Truck")])["BEV AP_A"] == 100.0
    cone = np.array([6.0, 1.0, 0.0, 0.4, 0.4, 1.0, 0.0])
    for cls in ("TrafficCone", "Bicycle"):
        near = command([cone + np.array([0.6, 0, 0, 0, 0, 0, 0])], [1.0], cone, cls)
        assert near.scored_as in ("Pedestrian", "Cyclist")
        assert top1_hits([near]).tolist() == [False]  # 0.6 m: beyond a small object's 0.5
    assert (top1_distance("Bus"), top1_distance("Barrier"), top1_distance("Car")) == (1.0, 0.5, 1.0)
    with pytest.raises(ValueError, match="referent class 'Tram'"):
        command([CAR], [1.0], CAR, "Tram")


def test_subsets_from_the_scene_description():
    assert subset_of("Rain, night, parked cars") == ("all", "rain", "night")
    assert subset_of("Heavy raining at the intersection") == ("all", "rain")
    assert subset_of("Nighttime, ped crossing") == ("all", "night")
    assert subset_of("Sunny, train station") == ("all",)
    assert subset_of("Fog, peds, parked cars") == ("all", "fog")
    assert subset_of("Foggy night") == ("all", "night", "fog")


def test_the_report_has_a_row_per_class_and_per_group_beyond_the_three(monkeypatch) -> None:
    """Per referent class, most commands first; "the three" and "beyond the three" only when
    some referent is beyond View-of-Delft's classes (a bicycle is one of the three)."""
    from types import SimpleNamespace

    from model.evaluation.talk2car.report import GROUPS, build_report

    def prediction(cls: str, hit: bool) -> SimpleNamespace:
        referent = np.array([10.0, 0, 0, 4, 2, 1.5, 0])
        boxes = referent[None] if hit else np.zeros((0, 7))
        answer = CommandBoxes.make(boxes, [0.9] * len(boxes), referent, cls)
        return SimpleNamespace(
            answer=answer,
            noun=answer,
            command=SimpleNamespace(box_2d=(0, 0, 10, 10)),
            frame=None,
            description="Rain, night",
            in_view_same_class=1,
            referent_in_view=True,
        )

    import model.evaluation.talk2car.report as report_module

    monkeypatch.setattr(report_module, "projected_2d_box", lambda box, frame: None)
    three = [prediction("Car", True), prediction("Car", False), prediction("Bicycle", True)]
    rows = build_report(three).rows
    assert list(rows)[3:] == ["Car", "Bicycle"] and not set(GROUPS) & set(rows)
    report = build_report([*three, prediction("Truck", True)])
    rows = report.rows
    assert rows["Car"]["commands"] == 2 and rows["Car"]["top-1"] == 50.0
    assert rows["the three"]["commands"] == 3 and rows["beyond the three"]["commands"] == 1
    assert rows["beyond the three"]["top-1"] == 100.0
    assert "beyond the three" in report.format_tables()
