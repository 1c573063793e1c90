"""The language suite (bench.studies.language_cases / language_score / language_suite): the data file's
schema and independence from the generator's sentences, the scoring rules, the fingerprint check,
and the runner end to end on two tiny scenes with a freshly built referent-path model."""

from __future__ import annotations

import json
import re
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from bench.studies.language_cases import (
    FAMILIES,
    SUITE_FILE,
    SuiteError,
    check_fingerprint,
    ensure_scenes,
    load_suite,
    parse_suite,
)
from bench.studies.language_score import Answer, oracle_outcome, score
from bench.studies.language_suite import main
from scenes.geometry.actors import Actor
from scenes.language.prompts import PromptConfig, generate_prompts
from scenes.language.resolve import resolve

TINY_ARGS = ["--frames", "2", "--prompts-per-world", "1", "--seed", "5"]
TINY_ARGS += ["--split-fractions", "0", "0", "1", "--no-camera", "--quiet"]


def _normal(text: str) -> str:
    return " ".join(re.findall(r"[a-z0-9]+", text.lower()))


def test_suite_file_schema() -> None:
    suite = load_suite()
    assert len(suite.sentences) >= 200
    counts = Counter(s.family for s in suite.sentences)
    assert set(counts) == set(FAMILIES)
    assert min(counts.values()) >= 30, counts
    assert len({s.id for s in suite.sentences}) == len(suite.sentences)
    assert len({_normal(s.text) for s in suite.sentences}) == len(suite.sentences)
    # every query is one the resolver accepts (resolving on an empty scene raises nothing)
    for s in suite.sentences:
        assert resolve(s.query, []).ids == ()
    assert suite.fingerprint, "the suite file records its scenes"


def _random_world(rng: np.random.Generator, n: int) -> list[Actor]:
    sizes = {"Car": (4.4, 1.8, 1.5), "Pedestrian": (0.6, 0.6, 1.7), "Cyclist": (1.8, 0.6, 1.7)}
    out = []
    for i in range(n):
        cls = ("Car", "Pedestrian", "Cyclist")[int(rng.integers(3))]
        x, y = rng.uniform(2, 48), rng.uniform(-15, 15)
        speed = 0.0 if rng.random() < 0.3 else rng.uniform(0.8, 12.0)
        heading = rng.uniform(-np.pi, np.pi)
        size = sizes[cls]
        box = [x, y, size[2] / 2, *size, heading]
        out.append(Actor(i, cls, box, [speed * np.cos(heading), speed * np.sin(heading)]))
    return out


def _generator_configs() -> list[PromptConfig]:
    """Every wording of the generator: its phrasings, and its languages where it has several
    (issue 23's extended language adds ``PromptConfig.language``)."""
    languages = ("base", "extended") if "language" in PromptConfig.__dataclass_fields__ else (None,)
    configs = [
        PromptConfig(phrasing=p) if lang is None else PromptConfig(phrasing=p, language=lang)
        for p in ("train", "heldout")
        for lang in languages
    ]
    if "command_share" in PromptConfig.__dataclass_fields__:  # issue 40's driving commands
        configs += [PromptConfig(phrasing=p, command_share=1.0) for p in ("train", "heldout")]
    return configs


def test_no_sentence_is_one_the_generator_writes() -> None:
    rng = np.random.default_rng(23)
    generated: set[str] = set()
    for config in _generator_configs():
        for _ in range(120):
            world = _random_world(rng, int(rng.integers(4, 14)))
            generated |= {_normal(p.text) for p in generate_prompts(world, rng, 8, config=config)}
    assert len(generated) > 1500
    clash = [s.text for s in load_suite().sentences if _normal(s.text) in generated]
    assert not clash, clash


def test_suite_errors_name_the_entry() -> None:
    data = json.loads(SUITE_FILE.read_text(encoding="utf-8"))
    bad = dict(data, sentences=[*data["sentences"][:3], dict(data["sentences"][0])])
    with pytest.raises(SuiteError, match=r"sentences\[3\]: id 'ooc-01'"):
        parse_suite(bad, "suite.json")
    entry = dict(data["sentences"][50], query={"class": "Car", "where": [{"op": "fly"}]})
    with pytest.raises(SuiteError, match=rf"{entry['id']}.query.where\[0\]: unknown op"):
        parse_suite(dict(data, sentences=[entry]), "suite.json")
    wrong = dict(data["sentences"][0], family="negation")
    with pytest.raises(SuiteError, match="out_of_class queries"):
        parse_suite(dict(data, sentences=[wrong]), "suite.json")


def test_scoring_rules() -> None:
    car = np.array([[10.0, 0.0, 0.0, 4.0, 2.0, 1.5, 0.0]])
    other = np.array([[20.0, 5.0, 0.0, 4.0, 2.0, 1.5, 0.0]])
    near, far = car.copy(), car.copy()
    near[0, 0] += 1.5
    far[0, 0] += 2.5
    both = Answer.of(np.r_[other, near], ("Car", "Car"), [0.9, 0.6])
    # top box is the other car: top-1 miss; the set {both} holds the referent 1.5 m off: F1 2/3
    out = score(both, car, ["Car"], threshold=0.5)
    assert (out.top1, out.empty, out.exact) == (0.0, False, False)
    assert out.f1 == pytest.approx(2 / 3)
    # a pedestrian box at the car's place matches nothing (class), and 2.5 m is past the limit
    assert score(Answer.of(car, ("Pedestrian",), [0.9]), car, ["Car"], 0.5).top1 == 0.0
    assert score(Answer.of(far, ("Car",), [0.9]), car, ["Car"], 0.5).f1 == 0
    # nothing above the threshold on an empty target: empty, F1 1, exact
    none = score(Answer.of(car, ("Car",), [0.3]), np.zeros((0, 7)), [], 0.5)
    assert (none.empty, none.f1, none.exact) == (True, 1.0, True)
    oracle = oracle_outcome(candidates=4, referents=1)
    assert (oracle.top1, oracle.f1, oracle.empty) == (0.25, 0.4, False)


def _tiny_suite(tmp_path: Path) -> tuple[Path, Path]:
    data = json.loads(SUITE_FILE.read_text(encoding="utf-8"))
    data["scenes"] = {"synth_args": TINY_ARGS, "fingerprint": []}
    path = tmp_path / "suite.json"
    path.write_text(json.dumps(data), encoding="utf-8")
    return path, tmp_path / "scenes"


def test_fingerprint_mismatch_is_a_clear_error(tmp_path: Path) -> None:
    path, scenes = _tiny_suite(tmp_path)
    suite = load_suite(path)
    root = ensure_scenes(suite, scenes)
    with pytest.raises(SuiteError, match=r"not the suite's scenes .*2 scenes, the suite expects 0"):
        check_fingerprint(suite, root)
    assert main(["--suite", str(path), "--scenes", str(scenes), "--write-fingerprint"]) == 0
    data = json.loads(path.read_text(encoding="utf-8"))
    data["scenes"]["fingerprint"][1]["hash"] = "0" * 16
    path.write_text(json.dumps(data), encoding="utf-8")
    with pytest.raises(SuiteError, match=r"scene 00001 differs"):
        check_fingerprint(load_suite(path), root)


def test_runner_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import torch

    from model import build_model, save_checkpoint

    path, scenes = _tiny_suite(tmp_path)
    assert main(["--suite", str(path), "--scenes", str(scenes), "--write-fingerprint"]) == 0
    torch.manual_seed(0)
    checkpoint = save_checkpoint(tmp_path / "m.pt", build_model("small", grounding="referent"))
    out = tmp_path / "suite-result.json"
    argv = ["--suite", str(path), "--scenes", str(scenes), "--checkpoint", str(checkpoint)]
    assert main([*argv, "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "operating threshold 0.5" in text  # an uncalibrated referent checkpoint
    for family in FAMILIES:
        rows = [r for r in text.splitlines() if r.startswith(f"| {family.replace('_', '-')} |")]
        assert rows, family
        assert all(int(r.split("|")[2]) > 0 for r in rows), rows
    result = json.loads(out.read_text(encoding="utf-8"))
    assert set(result["families"]["model"]) == set(FAMILIES)
    assert set(result["families"]) == {"model", "class noun", "oracle"}
    # the oracle's no-box rate on out-of-class sentences is 0: it boxes every object
    assert result["families"]["oracle"]["out_of_class"]["empty"] == 0.0
    assert len(result["per_sentence"]) == len(load_suite(path).sentences)
    # rewording cases were also grounded in the generator's own wording, the same cases
    pairs = result["rewording_vs_generator_wording"]
    assert pairs["generator wording"]["cases"] == pairs["rewording, same cases"]["cases"] > 0
    assert "generator wording" in text
