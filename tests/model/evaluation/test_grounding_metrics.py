"""Grounding metrics (model/evaluation/grounding.py), the baselines (model/evaluation/baselines.py) and the
grounding output of ``python -m model.evaluate --data ROOT``.

Boxes are axis-aligned (yaw 0) and equal in size, shifted along x by ``d``, so their 3D IoU is
``(l - d) / (l + d)``: for a 4 m car, ``d = 1`` gives 0.6 and ``d = 2`` gives 1/3; for a 0.8 m
pedestrian, ``d = 0.2`` gives 0.6.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from model.evaluation.baselines import class_noun_prompt, named_class, oracle_boxes, unsensed_ids
from model.evaluation.grounding import (
    PromptBoxes,
    grounding_metrics,
    match_count,
    prompt_outcome,
    summarize,
)
from scenes.geometry.actors import Actor
from scenes.geometry.boxes import iou3d
from scenes.language.prompts import DEFAULT_REGION
from scenes.synth.generate import SynthSettings, generate_root
from scenes.talk2radar.root import Talk2RadarRoot

CAR = np.array([20.0, 0.0, -0.9, 4.0, 1.8, 1.5, 0.0])
PED = np.array([10.0, 3.0, -0.9, 0.8, 0.8, 1.7, 0.0])


def shifted(box: np.ndarray, dx: float) -> np.ndarray:
    return box + np.array([dx, 0, 0, 0, 0, 0, 0])


def boxes(rows: list[tuple[np.ndarray, str, float]]) -> PromptBoxes:
    if not rows:
        return PromptBoxes.make(np.zeros((0, 7)), [], [])
    return PromptBoxes.make(
        np.stack([r[0] for r in rows]), [r[1] for r in rows], [r[2] for r in rows]
    )


def test_iou_construction():
    assert iou3d(CAR[None], shifted(CAR, 1.0)[None])[0, 0] == pytest.approx(0.6)
    assert iou3d(CAR[None], shifted(CAR, 2.0)[None])[0, 0] == pytest.approx(1 / 3)
    assert iou3d(PED[None], shifted(PED, 0.2)[None])[0, 0] == pytest.approx(0.6)


def test_perfect_answer():
    refs = boxes([(CAR, "Car", 1.0), (PED, "Pedestrian", 1.0)])
    pred = boxes([(PED, "Pedestrian", 0.9), (shifted(CAR, 1.0), "Car", 0.8)])
    o = prompt_outcome("00001", {"class", "depth"}, pred, refs, threshold=0.5)
    assert (o.hit_25, o.hit_50) == (1.0, 1.0)
    assert (o.num_referents, o.num_predicted, o.true_positives) == (2, 2, 2)
    assert o.precision == o.recall == o.f1 == 1.0 and o.exact
    assert o.groups() == ("attribute", "multiple")


def test_one_wrong_box():
    # The top box is the right class but 1/3 IoU: a hit at 0.25, not at 0.5, and no Car match.
    refs = boxes([(CAR, "Car", 1.0)])
    pred = boxes([(shifted(CAR, 2.0), "Car", 0.9)])
    o = prompt_outcome("1", {"class"}, pred, refs, threshold=0.3)
    assert (o.hit_25, o.hit_50) == (1.0, 0.0)
    assert (o.num_predicted, o.true_positives) == (1, 0)
    assert o.precision == o.recall == o.f1 == 0.0 and not o.exact
    assert o.groups() == ("class_only", "single")
    # The same box of the wrong class hits nothing, even at IoU 1.
    wrong = boxes([(CAR, "Pedestrian", 0.9)])
    o = prompt_outcome("1", {"class"}, wrong, refs, threshold=0.3)
    assert (o.hit_25, o.hit_50, o.true_positives) == (0.0, 0.0, 0)


def test_extra_box_and_the_operating_threshold():
    refs = boxes([(CAR, "Car", 1.0)])
    pred = boxes([(CAR, "Car", 0.9), (shifted(CAR, 15.0), "Car", 0.4)])
    above = prompt_outcome("1", {"position"}, pred, refs, threshold=0.3)
    assert (above.num_predicted, above.true_positives) == (2, 1)
    assert above.precision == 0.5 and above.recall == 1.0
    assert above.f1 == pytest.approx(2 / 3) and not above.exact
    below = prompt_outcome("1", {"position"}, pred, refs, threshold=0.5)
    assert (below.num_predicted, below.true_positives) == (1, 1) and below.exact
    # A score equal to the threshold is kept (the decoder's >= rule).
    at = prompt_outcome("1", {"position"}, pred, refs, threshold=0.4)
    assert at.num_predicted == 2


def test_empty_predictions_and_prompt_without_referents():
    refs = boxes([(CAR, "Car", 1.0)])
    o = prompt_outcome("1", {"class"}, boxes([]), refs, threshold=0.1)
    assert (o.hit_25, o.hit_50) == (0.0, 0.0)
    assert (o.num_predicted, o.true_positives) == (0, 0) and o.f1 == 0.0 and not o.exact
    nothing = prompt_outcome("2", {"class"}, boxes([]), boxes([]), threshold=0.1)
    assert nothing.hit_25 is None and nothing.f1 == 1.0 and nothing.exact
    assert nothing.groups() == ("class_only", "empty")
    spurious = prompt_outcome("3", {"class"}, boxes([(CAR, "Car", 0.9)]), boxes([]), 0.1)
    assert spurious.hit_25 is None and spurious.f1 == 0.0 and not spurious.exact
    s = summarize([o, nothing, spurious])
    assert s.prompts == 3 and s.acc_prompts == 1 and s.acc_25 == 0.0
    assert s.set_f1 == pytest.approx(100 / 3) and s.exact == pytest.approx(100 / 3)
    assert (s.referents, s.predicted, s.true_positives) == (1, 1, 0)
    empty = grounding_metrics([o, nothing, spurious], 0.1).by_group["empty"]
    assert empty.prompts == 2 and empty.exact == pytest.approx(50.0)  # one of two left empty


def test_multiple_referents_one_to_one_by_score():
    ped2 = shifted(PED, 3.0)
    refs = boxes([(PED, "Pedestrian", 1.0), (ped2, "Pedestrian", 1.0), (CAR, "Car", 1.0)])
    pred = boxes(
        [
            (shifted(PED, 0.2), "Pedestrian", 0.9),  # IoU 0.6 with PED: TP
            (PED, "Pedestrian", 0.8),  # IoU 1 with PED, but PED is taken and ped2 is far: FP
            (shifted(CAR, 2.0), "Car", 0.7),  # IoU 1/3 < Car's 0.5: FP, the car is missed
            (shifted(ped2, 0.2), "Pedestrian", 0.6),  # TP
        ]
    )
    assert match_count(pred, refs) == 2
    o = prompt_outcome("1", {"class", "motion"}, pred, refs, threshold=0.5)
    assert (o.hit_25, o.hit_50) == (1.0, 1.0)
    assert (o.num_referents, o.num_predicted, o.true_positives) == (3, 4, 2)
    assert o.precision == 0.5 and o.recall == pytest.approx(2 / 3)
    assert o.f1 == pytest.approx(4 / 7) and not o.exact


def test_greedy_order_is_by_score_not_input_order():
    # Two predictions on one referent: the higher-scored one takes it, even when listed second.
    refs = boxes([(PED, "Pedestrian", 1.0)])
    pred = boxes([(shifted(PED, 0.2), "Pedestrian", 0.5), (PED, "Pedestrian", 0.9)])
    assert match_count(pred, refs) == 1
    # The top box is the 0.9 one (IoU 1), although it is not first.
    far = boxes([(shifted(PED, 5.0), "Pedestrian", 0.5), (PED, "Pedestrian", 0.9)])
    assert prompt_outcome("1", {"class"}, far, refs, 0.1).hit_50 == 1.0


def test_tied_top_scores_count_the_expected_hit():
    refs = boxes([(CAR, "Car", 1.0)])
    pred = boxes([(CAR, "Car", 1.0), (shifted(CAR, 10.0), "Car", 1.0), (PED, "Pedestrian", 1.0)])
    o = prompt_outcome("1", {"class"}, pred, refs, threshold=0.5)
    assert o.hit_25 == pytest.approx(1 / 3) and o.hit_50 == pytest.approx(1 / 3)


def test_aggregates_and_splits():
    car_ref = boxes([(CAR, "Car", 1.0)])
    two = boxes([(PED, "Pedestrian", 1.0), (shifted(PED, 3.0), "Pedestrian", 1.0)])
    outcomes = [
        # class only, single, perfect
        prompt_outcome("a", {"class"}, boxes([(CAR, "Car", 0.9)]), car_ref, 0.5),
        # depth, single, wrong box: P 0, R 0, F1 0
        prompt_outcome(
            "b", {"class", "depth"}, boxes([(shifted(CAR, 9), "Car", 0.9)]), car_ref, 0.5
        ),
        # motion, two referents, one found: TP 1, P 1, R 2, F1 2/3
        prompt_outcome("c", {"motion"}, boxes([(PED, "Pedestrian", 0.9)]), two, 0.5),
    ]
    m = grounding_metrics(outcomes, 0.5)
    assert "empty" not in m.by_group
    o = m.overall
    assert o.prompts == 3 and o.acc_prompts == 3
    assert o.acc_25 == pytest.approx(200 / 3)
    assert (o.true_positives, o.predicted, o.referents) == (2, 3, 4)
    assert o.precision == pytest.approx(200 / 3) and o.recall == pytest.approx(50.0)
    assert o.f1 == pytest.approx(100 * 4 / 7)  # micro: 2 TP / (3 + 4) x 2
    assert o.set_f1 == pytest.approx(100 * (1 + 0 + 2 / 3) / 3)  # mean per prompt
    assert o.exact == pytest.approx(100 / 3)
    assert set(m.by_type) == {"class", "depth", "motion"}
    assert m.by_type["depth"].prompts == 1 and m.by_type["depth"].acc_25 == 0.0
    assert m.by_type["class"].prompts == 2
    assert {k: v.prompts for k, v in m.by_group.items()} == {
        "class_only": 1,
        "attribute": 2,
        "single": 2,
        "multiple": 1,
    }
    assert m.by_group["multiple"].set_f1 == pytest.approx(200 / 3)
    data = m.to_dict()
    assert data["operating_threshold"] == 0.5 and data["overall"]["prompts"] == 3
    assert set(data) == {"operating_threshold", "overall", "by_prompt_type", "by_group"}
    assert summarize([]).prompts == 0 and summarize([]).acc_25 == 0.0


def test_bad_input_names_the_source_and_field():
    with pytest.raises(ValueError, match=r"sample 7: boxes must have shape \(K, 7\)"):
        PromptBoxes.make(np.zeros((2, 6)), ["Car", "Car"], source="sample 7")
    with pytest.raises(ValueError, match="sample 7: 1 classes for 2 boxes"):
        PromptBoxes.make(np.zeros((2, 7)), ["Car"], source="sample 7")
    with pytest.raises(ValueError, match="sample 7: unknown class 'Tram'"):
        PromptBoxes.make(np.zeros((1, 7)), ["Tram"], source="sample 7")
    with pytest.raises(ValueError, match=r"scores must have shape \(1,\)"):
        PromptBoxes.make(np.zeros((1, 7)), ["Car"], [0.1, 0.2], source="sample 7")


# ------------------------------------------------------------------------------- baselines


def test_named_class_and_class_nouns():
    assert named_class({"class", "depth"}, ["Car", "Car"]) == "Car"
    assert named_class({"depth"}, ["Car"]) is None  # the prompt names no class
    assert named_class({"class"}, ["Car", "Cyclist"]) is None
    assert named_class({"class"}, []) is None
    assert class_noun_prompt("Pedestrian") == "the pedestrians"
    assert class_noun_prompt(None) == "the objects"
    with pytest.raises(ValueError, match="no class noun"):
        class_noun_prompt("Tram")


def test_oracle_keeps_the_named_class_in_the_region():
    def actor(i: int, cls: str, x: float, y: float) -> Actor:
        box = CAR if cls == "Car" else PED
        return Actor(i, cls, np.r_[x, y, box[2:]], np.zeros(2))

    actors = [
        actor(0, "Car", 20.0, 0.0),
        actor(1, "Car", 20.0, 30.0),  # bearing 56 degrees: outside the camera's field
        actor(2, "Car", 60.0, 0.0),  # beyond 50 m
        actor(3, "Pedestrian", 10.0, 2.0),
        actor(4, "Car", 30.0, -5.0),
    ]
    cars = oracle_boxes(actors, "Car")
    assert cars.classes == ("Car", "Car") and np.all(cars.scores == 1.0)
    np.testing.assert_allclose(cars.boxes[:, 0], [20.0, 30.0])
    assert len(oracle_boxes(actors, None)) == 3
    assert len(oracle_boxes(actors, "Car", exclude={4})) == 1
    assert len(oracle_boxes([], "Car")) == 0


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("grounding") / "root"
    # Seed 14: 9 prompts, some class-only, some with several referents (checked below).
    generate_root(root, 9, SynthSettings(seed=14, prompts_per_world=3), split_fractions=(0, 0, 1))
    return root


def test_oracle_on_a_synthetic_root(tiny_root):
    root = Talk2RadarRoot(tiny_root)
    outcomes = []
    class_only = 0
    for sid in root.ids("test"):
        sample = root.load(sid)
        meta = sample.meta
        assert meta is not None
        cls = named_class(meta.tags, sample.classes)
        skip = unsensed_ids(meta)
        answer = oracle_boxes(meta.actors, cls, exclude=skip)
        expected = {
            a.actor_id
            for a in meta.actors
            if (cls is None or a.cls == cls)
            and a.actor_id not in skip
            and DEFAULT_REGION.contains(a)
        }
        assert len(answer) == len(expected)
        assert set(meta.referent_ids) <= expected  # every referent is among the oracle's boxes
        refs = PromptBoxes.make(sample.boxes, sample.classes)
        o = prompt_outcome(sid, meta.tags, answer, refs, threshold=0.5)
        # A perfect detector finds every referent; its extra boxes are the other actors of the class.
        assert o.true_positives == o.num_referents == len(meta.referent_ids)
        assert o.num_predicted == len(expected)
        if not o.is_attribute:
            class_only += 1
            assert o.exact, f"{sid}: a class-only prompt refers to every actor of its class"
        outcomes.append(o)
    assert summarize(outcomes).recall == 100.0
    assert class_only >= 1  # the exact-set check above ran


# ------------------------------------------------------------------------- model.evaluate CLI


def test_evaluate_prints_and_writes_the_grounding_metrics(tiny_root, tmp_path, capsys):
    from model.evaluate import main

    out, report = tmp_path / "preds", tmp_path / "report.json"
    args = ["--data", str(tiny_root), "--limit", "4", "--out", str(out), "--json", str(report)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "operating threshold" in printed and "Grounding per prompt" in printed
    for row in ("model", "class noun", "oracle"):
        assert f"\n{row} " in printed
    data = json.loads(report.read_text())
    assert {"entire_area", "roi", "by_prompt_type", "grounding", "baselines"} <= set(data)
    g = data["grounding"]
    assert g["overall"]["prompts"] == 4 and 0.0 <= g["overall"]["acc_25"] <= 100.0
    assert {"acc_25", "acc_50", "precision", "recall", "f1", "set_f1", "exact"} <= set(g["overall"])
    assert set(data["baselines"]) == {"class_noun", "oracle"}
    oracle = data["baselines"]["oracle"]
    assert oracle["grounding"]["overall"]["recall"] == 100.0 and "mAP_3d" in oracle["entire_area"]
    assert oracle["grounding"]["operating_threshold"] == g["operating_threshold"]
    assert sorted(p.stem for p in out.glob("*.txt")) == Talk2RadarRoot(tiny_root).ids("test")[:4]
    # --threshold overrides the checkpoint's operating threshold; --no-baselines drops the rows.
    again = tmp_path / "again.json"
    args = ["--data", str(tiny_root), "--limit", "2", "--out", str(tmp_path / "p2")]
    assert main([*args, "--json", str(again), "--threshold", "0.9", "--no-baselines"]) == 0
    data = json.loads(again.read_text())
    assert data["grounding"]["operating_threshold"] == 0.9 and data["baselines"] == {}
    assert main([*args, "--threshold", "1.5"]) == 2
    assert "--threshold must be in [0, 1)" in capsys.readouterr().err
