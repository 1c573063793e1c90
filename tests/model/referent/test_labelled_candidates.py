"""Labelled boxes are ground truth (issue 37): a labelled candidate's class is its label's and its
score certain, whatever the detector makes of the frame; the ``--freeze-scene`` stage trains on
such candidate sets too (labelled views, some boxes reading another candidate's pooled features)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bench.studies.labelled_shift import blind_detector as blind
from model import LabelledBoxes
from model.checkpoint import load_checkpoint
from model.core.candidates import SceneCandidates
from model.core.labelled import LABELLED_SCORE
from model.evaluation.class_prompt_counts import CLASS_PROMPTS
from model.evaluation.predict import operating_threshold
from model.referent.candidates import LIDAR_EVIDENCE, RADAR_EVIDENCE
from model.training.referent_cache import CachedScene, scene_views, shift_evidence
from model.training.referent_step import model_frame
from scenes.geometry.actors import CLASSES
from scenes.geometry.ground import estimate_ground, unlevel_boxes
from scenes.language.prompts.features import DEFAULT_REGION
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.talk2radar.scene_labels import SceneLabels

SHIPPED = "checkpoints/tpcnet-small.pt"


@pytest.fixture(scope="module")
def shipped():
    model = load_checkpoint(SHIPPED)
    model.eval()
    return model


def test_a_labelled_candidate_is_certain_and_of_its_label_class(shipped, real_format_roots):
    _, vod = real_format_roots
    sid = Talk2RadarRoot(vod).ids("train")[0]
    sample = Talk2RadarRoot(vod).load(sid)
    boxes, labels = SceneLabels(vod).load(sid).metric()
    # every label claims to be a pedestrian: the candidates must say so, not what the detector sees
    claimed = np.full(len(labels), CLASSES.index("Pedestrian"))
    with blind(shipped):
        feats = shipped.encode_scene(
            sample.lidar, sample.radar, candidates=LabelledBoxes(boxes, claimed)
        )
    objects = feats.objects
    assert objects is not None and feats.answerable == len(boxes)
    assert objects.labels[: len(boxes)].tolist() == claimed.tolist()
    assert np.all(objects.scores[: len(boxes)] == LABELLED_SCORE)
    geometry = objects.geometry[: len(boxes)].numpy()
    assert np.all(geometry[:, CLASSES.index("Pedestrian")] == 1.0)
    assert np.all(geometry[:, 3] == LABELLED_SCORE)  # the score column


def test_class_prompts_over_labelled_boxes_hold_when_the_detector_sees_nothing(
    shipped, real_format_roots
):
    """The done-when check: a frame whose detector heatmap is forced to zero; each class prompt
    over its labelled boxes returns exactly the labelled objects of that class (a frame without
    one: nothing) that prompts can refer to (the generator's and Talk2Radar's referable region,
    :data:`scenes.language.prompts.features.DEFAULT_REGION`: a box whose centre lies just outside
    the camera's half field of view is labelled by VoD's rule but never a referent, and the model
    may leave it out; it must never answer a box of another class). On the code before issue 37
    a labelled box took the detector's score at its anchor (0 here), and the answers were
    empty."""
    _, vod = real_format_roots
    root = Talk2RadarRoot(vod)
    threshold = operating_threshold(shipped)
    asked = 0
    for sid in sorted(root.ids("train") + root.ids("val") + root.ids("test")):
        sample = root.load(sid)
        boxes, labels = SceneLabels(vod).load(sid).metric()
        with blind(shipped):
            feats = shipped.encode_scene(
                sample.lidar, sample.radar, candidates=LabelledBoxes(boxes, labels)
            )
        assert feats.answerable == len(boxes) == len(feats.objects)  # no proposals: no context
        region = DEFAULT_REGION
        bearing = np.degrees(np.arctan2(boxes[:, 1], boxes[:, 0]))
        referable = (region.x_min <= boxes[:, 0]) & (boxes[:, 0] <= region.x_max)
        referable &= np.abs(bearing) <= region.half_fov_deg
        for cls, prompt in CLASS_PROMPTS.items():
            pred = shipped.ground(feats, prompt, score_threshold=threshold)
            of_class = labels == CLASSES.index(cls)
            want = set(np.flatnonzero(of_class & referable).tolist())
            got = {int(np.argmin(np.abs(boxes - b).sum(axis=1))) for b in pred.boxes}
            assert want <= got <= set(np.flatnonzero(of_class).tolist()), (
                sid,
                prompt,
                sorted(got),
                sorted(want),
                np.round(pred.scores, 2),
            )
            asked += 1
    assert asked >= 9


def _scene(k: int, answerable: int | None) -> CachedScene:
    rng = np.random.default_rng(0)
    fused = torch.from_numpy(rng.normal(size=(k, 6)).astype(np.float32))
    lidar = torch.from_numpy(rng.normal(size=(k, 3 + LIDAR_EVIDENCE)).astype(np.float32))
    radar = torch.from_numpy(rng.normal(size=(k, 2 + RADAR_EVIDENCE)).astype(np.float32))
    geometry = torch.from_numpy(rng.normal(size=(k, 5)).astype(np.float32))
    cands = SceneCandidates(
        np.zeros((k, 7)), np.zeros(k, dtype=np.int64), np.ones(k), geometry, fused, lidar, radar
    )
    return CachedScene(cands, np.arange(k), ("the car",), (np.zeros(k, np.float32),), answerable)


def test_shift_evidence_moves_only_the_pooled_features_of_labelled_boxes():
    scene = _scene(6, answerable=3)
    c = scene.candidates
    out = shift_evidence(scene, np.random.default_rng(1), share=1.0).candidates
    assert torch.equal(out.geometry, c.geometry)
    # explicit evidence (point counts, radar motion) stays each box's own
    assert torch.equal(out.lidar[:, -LIDAR_EVIDENCE:], c.lidar[:, -LIDAR_EVIDENCE:])
    assert torch.equal(out.radar[:, -RADAR_EVIDENCE:], c.radar[:, -RADAR_EVIDENCE:])
    # context rows untouched, every labelled row reads another candidate's pooled features
    assert torch.equal(out.fused[3:], c.fused[3:])
    for i in range(3):
        donors = [j for j in range(6) if torch.equal(out.fused[i], c.fused[j])]
        assert donors and i not in donors
        j = donors[0]
        assert torch.equal(out.lidar[i, :3], c.lidar[j, :3])
        assert torch.equal(out.radar[i, :2], c.radar[j, :2])
    # a detector view, or share 0, comes back as is
    assert shift_evidence(_scene(6, None), np.random.default_rng(1), 1.0).candidates is not None
    assert torch.equal(
        shift_evidence(_scene(6, None), np.random.default_rng(1), 1.0).candidates.fused,
        _scene(6, None).candidates.fused,
    )
    assert shift_evidence(scene, np.random.default_rng(1), 0.0) is scene


def test_scene_views_describe_detector_and_labelled_candidates_from_one_pass(
    shipped, real_format_source
):
    from scenes.datasets.frames import FrameDataset

    raw = FrameDataset(Talk2RadarRoot(real_format_source), "train")[0]
    # the frame as training shows it to the model (levelled when its ground is estimated),
    # described as encode_scene describes it at inference (which moves its answer boxes back)
    item = model_frame(shipped, raw)
    objects, view = scene_views(shipped, item.lidar, item.radar, item.actors, labelled=True)
    plain = shipped.encode_scene(raw.lidar, raw.radar).objects
    boxes = objects.boxes
    if shipped.cfg.pillars.ground == "estimated":
        height = shipped.cfg.pillars.ground_height
        boxes = unlevel_boxes(boxes, estimate_ground(raw.lidar, height), height)
    np.testing.assert_allclose(boxes, plain.boxes, atol=1e-5)
    assert torch.allclose(objects.geometry, plain.geometry)
    assert view is not None
    lab, ids = view
    metric = [a for a in item.actors if a.cls in CLASSES]
    inside = shipped.scene.anchors_in_grid(np.stack([a.box for a in metric]))
    n = int(inside.sum())
    assert ids[:n].tolist() == [a.actor_id for a, ok in zip(metric, inside, strict=True) if ok]
    assert np.all(ids[n:] == -1)
    assert np.all(lab.scores[:n] == LABELLED_SCORE)
    _, none = scene_views(shipped, item.lidar, item.radar, item.actors, labelled=False)
    assert none is None
