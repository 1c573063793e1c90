"""The annotation store under hostile text and repeated requests (issue 21): the text policy on
every save path, a fuzz of prompts and annotator names that may never leave a control character
or a second line on disk, and saves that are idempotent per request key."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pytest

from annotate import AnnotationStore, Draft, SourceFrame, ValidationError
from scenes.talk2radar.layout import PROMPT, sample_file
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.utils.text_policy import forbidden_characters

SEED = 21
FUZZ_CASES = 40

POOL = (
    list("abcdefghij klmnop") * 4
    + list("\t\n\r\x00\x0b\x0c\x1c\x1d\x1e\x1f\x85\x7f\x9b\u2028\u2029\u200b\u202e\ufeff")
    + ["１", "５", "é", "e\u0301", "🚗", "\u00a0", "ß", "ﬁ"]
)
"""Characters the fuzz draws from: plain text, every kind of forbidden character, and text that
NFKC changes."""


@pytest.fixture
def store_and_source(tmp_path: Path, write_tiny_root, gt_box) -> tuple[AnnotationStore, object]:
    root = write_tiny_root(tmp_path / "source", frames=1)
    source = SourceFrame.from_root(Talk2RadarRoot(root), Talk2RadarRoot(root).ids("test")[0])
    return AnnotationStore(tmp_path / "pairs"), source


def _draft(gt_box: np.ndarray, prompt: str = "the car ahead") -> Draft:
    return Draft().set_prompt(prompt).add_box(gt_box, "Car")


def _texts(root: Path) -> dict[Path, str]:
    """Every text file the store wrote (prompt files, sidecars, the manifest, split lists)."""
    out = {}
    for path in root.rglob("*"):
        if path.is_file() and path.suffix in (".txt", ".json", ".jsonl"):
            out[path] = path.read_text(encoding="utf-8")
    return out


@pytest.mark.parametrize(
    "prompt, annotator, field, says",
    [
        ("the car\x00ahead", "ada", "prompt", "U+0000 (NUL)"),
        ("the car\u2028ahead", "ada", "prompt", "U+2028 (LINE SEPARATOR)"),
        ("the car\x0b\x0c\x1c\x85ahead", "ada", "prompt", "U+0085 (NEL)"),
        ("x" * 1_000_000, "ada", "prompt", "at most 500"),
        ("the car ahead", "ada\x00bob", "annotator", "U+0000 (NUL)"),
        ("the car ahead", "a" * 1_000_000, "annotator", "at most 64"),
    ],
)
def test_hostile_text_is_refused_before_anything_is_written(
    store_and_source, gt_box, prompt: str, annotator: str, field: str, says: str
) -> None:
    store, source = store_and_source
    before = _texts(store.path)
    with pytest.raises(ValidationError) as err:
        store.save(_draft(gt_box, prompt), source, annotator=annotator)
    issue = next(i for i in err.value.issues if i.field == field)
    assert says in issue.message
    assert _texts(store.path) == before and store.pairs() == ()


def test_saved_text_is_in_the_policy_form(store_and_source, gt_box) -> None:
    store, source = store_and_source
    result = store.save(
        _draft(gt_box, "  the car\tabout １５ m\u00a0ahead "), source, annotator="  Ａda  "
    )
    sid = result.sample_id
    prompt_file = sample_file(store.lidar_dir, PROMPT, sid)
    assert prompt_file.read_text(encoding="utf-8") == "the car about 15 m ahead\n"
    record = store.history(sid)[-1]
    assert record.prompt == "the car about 15 m ahead" and record.annotator == "Ada"
    assert Talk2RadarRoot(store.path).load(sid).prompt == "the car about 15 m ahead"


def test_fuzzed_text_never_reaches_the_disk_unclean(store_and_source, gt_box) -> None:
    store, source = store_and_source
    rng = np.random.default_rng(SEED)
    saved = refused = 0
    for _ in range(FUZZ_CASES):
        prompt = "car " + "".join(rng.choice(POOL, int(rng.integers(1, 30))))
        name = "".join(rng.choice(POOL, int(rng.integers(0, 12))))
        try:
            store.save(_draft(gt_box, prompt), source, annotator=name)
            saved += 1
        except ValidationError:
            refused += 1
    assert saved and refused  # both kinds happened
    assert len(store.pairs()) == saved
    for path, text in _texts(store.path).items():
        assert not forbidden_characters(text.replace("\n", "")), path
        if path.parent.name == "prompt":
            assert len(text.splitlines()) == 1 and len(text) <= 501, path
    for line in (store.path / "annotations" / "manifest.jsonl").read_text().splitlines():
        record = json.loads(line)
        assert not forbidden_characters(record["prompt"] + record["annotator"])
        assert len(record["prompt"]) <= 500 and len(record["annotator"]) <= 64


def test_two_saves_of_one_request_at_once_save_once(store_and_source, gt_box) -> None:
    store, source = store_and_source
    draft = _draft(gt_box)
    barrier = threading.Barrier(4)
    results = []

    def save() -> None:
        barrier.wait()
        results.append(store.save(draft, source, annotator="ada", request="tab-1:7"))

    threads = [threading.Thread(target=save) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert len(results) == 4 and len(store.pairs()) == 1
    assert {r.sample_id for r in results} == {store.pairs()[0].sample_id}
    assert sorted(r.repeated for r in results) == [False, True, True, True]


def test_a_request_that_succeeded_is_answered_not_repeated(store_and_source, gt_box) -> None:
    store, source = store_and_source
    first = store.save(_draft(gt_box), source, request="tab-1:1")
    again = store.save(_draft(gt_box), source, request="tab-1:1")
    assert again.repeated and again.sample_id == first.sample_id and len(store.pairs()) == 1
    other = store.save(_draft(gt_box), source, request="tab-1:2")  # a new version saves
    assert other.sample_id != first.sample_id and len(store.pairs()) == 2
    with pytest.raises(ValueError, match="made before for something else"):
        store.save(_draft(gt_box, "another prompt"), source, request="tab-1:1")


def test_a_failed_request_may_be_tried_again(store_and_source, gt_box) -> None:
    store, source = store_and_source
    with pytest.raises(ValidationError):
        store.save(_draft(gt_box), source, annotator="ada\x00", request="tab-1:3")
    result = store.save(_draft(gt_box), source, annotator="ada", request="tab-1:3")
    assert not result.repeated and len(store.pairs()) == 1
