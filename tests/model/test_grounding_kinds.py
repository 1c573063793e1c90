"""The two grounding kinds are told apart in one place (issue 35, item 3): ``model.tpcnet.head_class``
picks the head; thresholds and candidates are asked of the head, training of the strategy kept
for its class (``model.training.kinds``)."""

from __future__ import annotations

import re
import types

import pytest

from model.evaluation.predict import operating_threshold
from model.grounding.paper import PaperGrounding
from model.grounding.referent import UNCALIBRATED_REFERENT, ReferentGrounding
from model.tpcnet import head_class
from model.training.config import TrainingError
from model.training.kinds import PaperTraining, ReferentTraining, training_kind
from tests.paths import REPO

KIND_BRANCH = re.compile(r"grounding\s*(==|!=)|\"grounding\",[^)]*\)\s*(==|!=)")
"""A comparison of a grounding kind (``cfg.grounding == "referent"`` and the like)."""


def test_only_head_class_tells_the_kinds_apart() -> None:
    found = []
    for package in ("model", "app"):
        for path in sorted((REPO / package).rglob("*.py")):
            for number, line in enumerate(path.read_text().splitlines(), 1):
                if KIND_BRANCH.search(line):
                    found.append(f"{path.relative_to(REPO)}:{number}: {line.strip()}")
    assert len(found) == 1 and found[0].startswith("model/tpcnet.py:"), "\n".join(found)
    assert head_class("referent") is ReferentGrounding
    assert head_class("tpcnet") is PaperGrounding


@pytest.mark.parametrize("grounding", ["tpcnet", "referent"])
def test_an_uncalibrated_checkpoint_answers_at_its_heads_threshold(
    untrained_model, grounding: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    model = untrained_model(grounding, text_encoder="gru")
    model.checkpoint_metadata = {}
    head = model.grounding
    expected = UNCALIBRATED_REFERENT if grounding == "referent" else model.cfg.head.score_threshold
    assert operating_threshold(model) == head.uncalibrated_threshold == expected
    monkeypatch.setattr(type(head), "uncalibrated_threshold", property(lambda _: 0.123))
    assert operating_threshold(model) == 0.123  # asked of the head, not re-derived
    assert model.takes_labelled_candidates is (grounding == "referent")


def test_each_head_trains_by_its_own_strategy() -> None:
    paper = types.SimpleNamespace(grounding="tpcnet", data=("a", "b"), scene_labels=None)
    referent = types.SimpleNamespace(grounding="referent", data=("a", "b"), scene_labels=None)
    assert isinstance(training_kind(paper), PaperTraining)
    assert isinstance(training_kind(referent), ReferentTraining)
    assert training_kind(referent).calibrates and not training_kind(paper).calibrates
    training_kind(referent).check(referent)
    with pytest.raises(TrainingError, match="several --data roots"):
        training_kind(paper).check(paper)
