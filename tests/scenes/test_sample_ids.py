"""One frame-id rule for every reader and command (issue 21): exactly 5 ASCII digits.

``scenes.talk2radar.layout`` holds the rule; the split-list reader (``Talk2RadarRoot.ids``), ``launch.py``,
``model.evaluate`` (split lists and label / prediction file names) and ``model.evaluation.class_prompts``
(label file names) refuse the same entries with one line naming the file (and line).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scenes.frame import RootError
from scenes.talk2radar.layout import format_id, is_frame_id, parse_id, parse_split_list
from scenes.talk2radar.root import Talk2RadarRoot

BAD = [
    "0_0010",  # int() reads it as 10
    "\u0660\u0660\u0660\u0661\u0660",  # Arabic-Indic 00010
    "\u0664",  # Arabic-Indic 4
    "+4",
    "-6",
    " 00004",
    "00004 ",
    "0000\t4",
    "000010",  # 6 digits: int() reads it as 10
    "123456",
    "4",  # unpadded: files write 00004
    "0x1f",
    "1e3",
    "00004.",
]
"""Entries refused in a split list or as a file stem."""


@pytest.mark.parametrize("text", BAD)
def test_only_five_ascii_digits_are_a_frame_id(text: str) -> None:
    assert not is_frame_id(text)
    with pytest.raises(RootError, match="expected 5 ASCII digits"):
        parse_id(text)


def test_format_id_pads_numbers_and_refuses_the_rest() -> None:
    assert parse_id("00042") == "00042" and is_frame_id("99999")
    assert format_id(7) == "00007" == format_id("7") == format_id(np.int64(7))
    assert format_id("00042") == "00042" and format_id(99999) == "99999"
    for bad in ("0_0010", "\u0664", "+4", "-6", " 4", "000010", "", True, 4.0, -1, 100000):
        with pytest.raises(RootError, match="invalid sample id"):
            format_id(bad)  # type: ignore[arg-type]


def test_split_list_names_file_and_line() -> None:
    path = Path("root/lidar/ImageSets/train.txt")
    assert parse_split_list("00001\n\n00002\n   \n", path) == ["00001", "00002"]
    with pytest.raises(RootError, match=r"train\.txt:3: invalid sample id '\+4'"):
        parse_split_list("00001\n00002\n+4\n", path)
    with pytest.raises(RootError, match=r"train\.txt:2: sample 00001 is listed twice"):
        parse_split_list("00001\n00001\n", path)


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory, write_tiny_root) -> Path:
    return write_tiny_root(tmp_path_factory.mktemp("ids") / "root", frames=2)


def _list(root: Path, entries: str) -> Path:
    split = root / "lidar" / "ImageSets" / "odd.txt"
    split.write_text(entries, encoding="utf-8")
    return split


@pytest.mark.parametrize("text", BAD)
def test_the_reader_refuses_a_lenient_id(root: Path, text: str) -> None:
    split = _list(root, f"00000\n{text}\n")
    with pytest.raises(RootError) as caught:
        Talk2RadarRoot(root).ids("odd")
    message = str(caught.value)
    assert message.startswith(f"{split}:2: invalid sample id ") and "\n" not in message


def _error_lines(capsys: pytest.CaptureFixture) -> list[str]:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return [line for line in err.splitlines() if line.startswith("error: ")]


@pytest.mark.parametrize("text", ["0_0010", "\u0664", "000010"])
def test_launch_and_evaluate_refuse_it_in_one_line(
    root: Path, tmp_path: Path, capsys: pytest.CaptureFixture, text: str
) -> None:
    import launch
    from model import evaluate

    split = _list(root, f"00000\n{text}\n")
    assert launch.main(["--data", str(root), "--split", "odd", "--port", "0"]) == 2
    lines = _error_lines(capsys)
    assert len(lines) == 1 and f"{split}:2: invalid sample id" in lines[0], lines
    args = ["--data", str(root), "--split", "odd", "--out", str(tmp_path / "p")]
    assert evaluate.main(args) == 2
    lines = _error_lines(capsys)
    assert len(lines) == 1 and f"{split}:2: invalid sample id" in lines[0], lines
    assert not (tmp_path / "p").exists()


@pytest.mark.parametrize("stem", ["000010", "\u0660\u0660\u0660\u0661\u0660", "+0010", "0_010"])
def test_file_names_follow_the_same_rule(
    root: Path, tmp_path: Path, capsys: pytest.CaptureFixture, stem: str
) -> None:
    """``model.evaluate --labels/--preds`` and ``model.evaluation.class_prompts`` (split ``all``) read ids
    from file names: a 6-digit or non-ASCII stem is refused by both, naming the file."""
    from model import evaluate
    from scenes.datasets.family_files import labelled_frame_ids

    labels, preds = tmp_path / "labels", tmp_path / "preds"
    labels.mkdir()
    preds.mkdir()
    (labels / "00001.txt").write_text("")
    odd = labels / f"{stem}.txt"
    odd.write_text("")
    assert evaluate.main(["--labels", str(labels), "--preds", str(preds)]) == 2
    lines = _error_lines(capsys)
    assert len(lines) == 1 and str(odd) in lines[0] and "5-digit frame id" in lines[0], lines
    label_dir = root / "lidar" / "training" / "label_2"
    named = label_dir / f"{stem}.txt"
    named.write_text("")
    try:
        with pytest.raises(RootError, match="not named by a 5-digit frame id"):
            labelled_frame_ids(Talk2RadarRoot(root), "all")
    finally:
        named.unlink()


def test_the_annotation_store_reads_split_lists_by_the_one_id_rule():
    from annotate.tree import int_or_none

    assert int_or_none("00042") == 42
    for bad in ("٤٢٠٠٠", "42", "0_0010", "+0004", "000042"):
        assert int_or_none(bad) is None, bad
