"""Fuzz-style robustness (issue 11): a few hundred random malformed label, calib, prompt, sidecar,
split-list and point files fed to the reader (:meth:`scenes.talk2radar.root.Talk2RadarRoot.load`) and the
evaluator (``python -m model.evaluate --labels --preds``). Each either loads or raises the
project's error type for that kind of file, with one line naming the file; never another
exception, never a hang (each case runs under a timer).

The mutations start from valid files written by the project's own writers: truncation, tokens
replaced by NaN / infinities / huge or tiny numbers / words / non-ASCII digits, tokens dropped or
repeated, lines dropped or repeated, invalid UTF-8, NUL bytes, random bytes, an empty file, and the
file replaced by a folder, a symlink loop or a dangling link.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import signal
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from model.evaluate import main
from model.evaluation.files import EvaluationInputError, score_directories
from scenes.frame import RootError
from scenes.frame.kitti import LabelError, format_label_line, read_label_file
from scenes.frame.sample_meta import SampleMeta
from scenes.geometry.actors import Actor
from scenes.geometry.calib import CalibrationError
from scenes.talk2radar.layout import (
    CALIB,
    LABEL,
    LIDAR_FOLDER,
    PROMPT,
    RADAR_FOLDERS,
    VELODYNE,
    meta_file,
    sample_dir,
    sample_file,
    split_file,
)
from scenes.talk2radar.pointcloud import PointCloudError
from scenes.talk2radar.root import Talk2RadarRoot

SEED = 11
CASES_PER_FILE = 40
"""Cases per reader file (9 files) and per evaluator folder (2): 440 in all."""

CASE_SECONDS = 20
"""A case running longer than this is a hang (real cases take milliseconds)."""

READER_ERRORS = (RootError, LabelError, CalibrationError, PointCloudError)
EVALUATOR_ERRORS = (LabelError, EvaluationInputError)

TOKENS = (
    "nan", "NaN", "inf", "-inf", "1e400", "-1e400", "1e308", "-1e308", "1e-320", "0", "-0",
    "-1", "3.5", "", "x", "Car", "Cyclst", "DontCare", "١٢", "0x1F", "1_000", "--1", ".", "1e",
    "é", "🚗", "9" * 400, "P2:", ":", "\t", "\x00", "\u2028", "\x0b", "Tr_velo_to_cam:",
)  # fmt: skip
"""Replacement tokens."""


class HangError(Exception):
    """A case ran past its timer."""


@contextlib.contextmanager
def time_limit(seconds: int, what: str) -> Iterator[None]:
    def alarm(*_: object) -> None:
        raise HangError(f"{what} ran for more than {seconds} s")

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _mutate_text(rng: np.random.Generator, data: bytes) -> bytes:
    lines = data.split(b"\n")
    kind = int(rng.integers(0, 12))
    if kind == 0:  # truncate
        return data[: int(rng.integers(0, max(len(data), 1)))]
    if kind == 1:  # random bytes
        return rng.integers(0, 256, int(rng.integers(1, 200)), dtype=np.uint8).tobytes()
    if kind == 2:  # invalid UTF-8 or NUL somewhere
        at = int(rng.integers(0, len(data) + 1))
        bad = (b"\xff", b"\xc3\x28", b"\x00", b"\xed\xa0\x80")[int(rng.integers(0, 4))]
        return data[:at] + bad + data[at:]
    if kind == 3:
        return b"" if rng.random() < 0.5 else b" \n\t\r\n"
    if kind == 4 and lines:  # drop or repeat a line
        i = int(rng.integers(0, len(lines)))
        return b"\n".join(lines[:i] + lines[i + 1 :] if rng.random() < 0.5 else [*lines, lines[i]])
    # Token edits on one line: replace, drop or repeat a token, several times.
    text = data.decode("utf-8")
    rows = text.split("\n")
    for _ in range(int(rng.integers(1, 4))):
        r = int(rng.integers(0, len(rows)))
        tokens = rows[r].split(" ")
        t = int(rng.integers(0, len(tokens)))
        choice = rng.random()
        if choice < 0.6:
            tokens[t] = str(rng.choice(TOKENS))
        elif choice < 0.8:
            del tokens[t]
        else:
            tokens.insert(t, tokens[t])
        rows[r] = " ".join(tokens)
    return "\n".join(rows).encode("utf-8")


JSON_VALUES = (None, "x", "", 1e308, -1, 0, 2.5, True, [], {}, [1, 2], [[1]], {"a": 1}, "nan")
"""Values put into a sidecar."""


def _mutate_json(rng: np.random.Generator, data: bytes) -> bytes:
    """Half the time a text mutation; else valid JSON with one value (nested too) replaced."""
    if rng.random() < 0.5:
        return _mutate_text(rng, data)
    doc = json.loads(data)
    node = doc
    while True:
        keys = list(node.keys()) if isinstance(node, dict) else list(range(len(node)))
        if not keys:
            break
        key = keys[int(rng.integers(0, len(keys)))]
        child = node[key]
        if isinstance(child, dict | list) and child and rng.random() < 0.6:
            node = child
            continue
        node[key] = JSON_VALUES[int(rng.integers(0, len(JSON_VALUES)))]
        break
    return json.dumps(doc).encode("utf-8")


def _mutate_points(rng: np.random.Generator, data: bytes, features: int) -> bytes:
    kind = int(rng.integers(0, 6))
    if kind == 0:
        return data[: int(rng.integers(0, len(data)))]
    if kind == 1:
        return rng.integers(0, 256, int(rng.integers(1, 300)), dtype=np.uint8).tobytes()
    if kind == 2:
        return b""
    points = np.frombuffer(data, dtype="<f4").reshape(-1, features).copy()
    values = (np.nan, np.inf, -np.inf, 3.4e38, -3.4e38, 1e-45, 0.0)
    for _ in range(int(rng.integers(1, 5))):
        points[rng.integers(0, len(points)), rng.integers(0, features)] = rng.choice(values)
    if kind == 3:
        points = points[: int(rng.integers(0, len(points)))]
    return points.astype("<f4").tobytes()


def _place(rng: np.random.Generator, path: Path, data: bytes) -> None:
    """Write ``data`` at ``path`` (after removing what is there), or now and then put a folder,
    a symlink loop or a dangling link there instead."""
    if path.is_symlink() or path.is_file():
        path.unlink()
    elif path.is_dir():
        shutil.rmtree(path)
    roll = rng.random()
    if roll < 0.03:
        path.mkdir()
    elif roll < 0.06:
        path.symlink_to(path)
    elif roll < 0.08:
        path.symlink_to(path.with_name("missing-target"))
    else:
        path.write_bytes(data)


def _one_line_naming(exc: BaseException, path: Path) -> None:
    message = str(exc)
    assert "\n" not in message, message
    assert str(path) in message, f"{type(exc).__name__} does not name {path}: {message}"


@pytest.fixture(scope="module")
def reader_root(tmp_path_factory: pytest.TempPathFactory, write_tiny_root, gt_box) -> Path:
    """A tiny root whose sample 00001 also has a sidecar (with an actor) to mutate."""
    root = write_tiny_root(tmp_path_factory.mktemp("fuzz") / "root", frames=2)
    actor = Actor(0, "Car", gt_box, [3.0, 0.0])
    meta = SampleMeta(tags=frozenset({"class"}), actors=(actor,), extra={"annotator": "ada"})
    (root / "meta").mkdir(exist_ok=True)
    (root / "meta" / "00001.json").write_text(json.dumps(meta.to_json()))
    return root


_LIDAR, _RADAR = Path(LIDAR_FOLDER), Path(RADAR_FOLDERS[0])
READER_FILES = tuple(
    (str(path), kind)
    for path, kind in (
        (sample_file(_LIDAR, LABEL, "00001"), "text"),
        (sample_file(_LIDAR, CALIB, "00001"), "text"),
        (sample_file(_RADAR, CALIB, "00001"), "text"),
        (sample_file(_LIDAR, PROMPT, "00001"), "text"),
        (meta_file(Path(), "00001"), "json"),
        (split_file(_LIDAR, "test"), "text"),
        (sample_file(_LIDAR, VELODYNE, "00001"), 4),
        (sample_file(_RADAR, VELODYNE, "00001"), 7),
        (sample_file(_LIDAR, LABEL, "00000"), "text"),
    )
)


@pytest.mark.parametrize(("relative", "kind"), READER_FILES)
def test_reader_loads_or_names_the_file(reader_root: Path, relative: str, kind) -> None:
    rng = np.random.default_rng([SEED, READER_FILES.index((relative, kind))])
    path = reader_root / relative
    original = path.read_bytes()
    sid = "00000" if relative.endswith("00000.txt") else "00001"
    outcomes = {"loaded": 0, "refused": 0}
    try:
        for case in range(CASES_PER_FILE):
            if kind == "json":
                data = _mutate_json(rng, original)
            elif kind == "text":
                data = _mutate_text(rng, original)
            else:
                data = _mutate_points(rng, original, int(kind))
            _place(rng, path, data)
            with time_limit(CASE_SECONDS, f"{relative} case {case}"):
                try:
                    reader = Talk2RadarRoot(reader_root)
                    if relative.startswith("lidar/ImageSets"):
                        reader.ids("test")
                    else:
                        sample = reader.load(sid)
                        assert sample.sample_id == sid and sample.prompt
                    outcomes["loaded"] += 1
                except READER_ERRORS as exc:
                    _one_line_naming(exc, path)
                    outcomes["refused"] += 1
    finally:
        _restore(path, original)
    print(relative, outcomes)
    assert outcomes["refused"] > 0  # the mutations do break files


def _restore(path: Path, original: bytes) -> None:
    if path.is_symlink() or path.is_file():
        path.unlink()
    elif path.is_dir():
        shutil.rmtree(path)
    path.write_bytes(original)


@pytest.fixture
def score_folders(tmp_path: Path, write_tiny_root) -> tuple[Path, Path]:
    """Labels and predictions of 3 frames (cars and a cyclist, VoD-style lines)."""
    root = write_tiny_root(tmp_path / "root", frames=3)
    labels, preds = tmp_path / "labels", tmp_path / "preds"
    labels.mkdir()
    preds.mkdir()
    for label_file in sorted(sample_dir(root / LIDAR_FOLDER, LABEL).iterdir()):
        gt = read_label_file(label_file)
        gt = [*gt, replace(gt[0], name="Cyclist", location=(2.0, 1.6, 14.0))]
        (labels / label_file.name).write_text("".join(format_label_line(g) + "\n" for g in gt))
        dets = [
            replace(g, truncated=-1.0, occluded=-1, score=0.9 - 0.1 * i) for i, g in enumerate(gt)
        ]
        (preds / label_file.name).write_text("".join(format_label_line(d) + "\n" for d in dets))
    return labels, preds


@pytest.mark.parametrize("folder", ["labels", "preds"])
def test_evaluator_scores_or_names_the_file(
    score_folders: tuple[Path, Path], folder: str, capsys: pytest.CaptureFixture
) -> None:
    labels, preds = score_folders
    rng = np.random.default_rng([SEED, 100 + ("labels", "preds").index(folder)])
    target = (labels if folder == "labels" else preds) / "00001.txt"
    original = target.read_bytes()
    args = ["--labels", str(labels), "--preds", str(preds)]
    outcomes = {"scored": 0, "refused": 0}
    for case in range(CASES_PER_FILE):
        _place(rng, target, _mutate_text(rng, original))
        with time_limit(CASE_SECONDS, f"{folder} case {case}"):
            try:
                score_directories(labels, preds)
                expected = 0
            except EVALUATOR_ERRORS as exc:
                _one_line_naming(exc, target)
                expected = 2
            capsys.readouterr()
            assert main(args) == expected
            out, err = capsys.readouterr()
            if expected == 2:
                assert err.count("\n") == 1 and err.startswith("error: ") and str(target) in err
                outcomes["refused"] += 1
            else:
                assert "Entire annotated area" in out
                outcomes["scored"] += 1
    _restore(target, original)
    print(folder, outcomes)
    assert outcomes["refused"] > 0
