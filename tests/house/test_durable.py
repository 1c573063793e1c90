"""scenes.utils.durable: the temporaries' one naming rule, atomic writes (also when the write or its
fsync fails), links, multi-file replacement, and JSON Lines logs with a torn last line."""

from __future__ import annotations

import errno
import os
import stat
import threading
from pathlib import Path

import pytest

from scenes.utils import durable
from scenes.utils.durable import (
    append_json_line,
    append_line,
    atomic_file,
    atomic_write_bytes,
    atomic_write_text,
    drop_torn_tail,
    link_or_copy,
    read_json_lines,
    remove_temporaries,
    replace_files,
    temp_glob,
    temp_path,
)


def _names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def _enospc(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def _exdev(*args, **kwargs):
    raise OSError(errno.EXDEV, "Invalid cross-device link")


# ------------------------------------------------------------------------------------------ naming


def test_temporaries_have_one_name_beside_their_target(tmp_path: Path) -> None:
    tmp = temp_path(tmp_path / "00012.txt")
    assert tmp.parent == tmp_path
    assert tmp.name == f".00012.txt.{os.getpid()}.{threading.get_ident()}.tmp"
    assert tmp.match(temp_glob("00012.")) and tmp.match(temp_glob())
    assert not tmp.match(temp_glob("00120."))


def test_remove_temporaries_takes_only_the_named_targets_temporaries(tmp_path: Path) -> None:
    for name in ("00012.txt", "00012.bin", "00120.txt", "train.txt"):
        temp_path(tmp_path / name).write_text("left by a killed writer")
    (tmp_path / "00012.txt").write_text("a real file")
    (tmp_path / ".00012.txt.hidden").write_text("not a temporary")
    remove_temporaries(tmp_path, "00012.")
    left = _names(tmp_path)
    assert left == sorted(
        [
            "00012.txt",
            ".00012.txt.hidden",
            temp_path(tmp_path / "00120.txt").name,
            temp_path(tmp_path / "train.txt").name,
        ]
    )
    remove_temporaries(tmp_path)
    assert _names(tmp_path) == [".00012.txt.hidden", "00012.txt"]
    remove_temporaries(tmp_path / "missing")  # no folder, no temporaries


# ------------------------------------------------------------------------------------------ atomic


def test_atomic_write_replaces_and_syncs_the_file_and_its_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    target = tmp_path / "sub" / "label.txt"
    synced: list[bool] = []
    real = os.fsync

    def fsync(fd: int) -> None:
        synced.append(stat.S_ISDIR(os.fstat(fd).st_mode))
        real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    atomic_write_text(target, "Car 0 0 ü\n")
    assert target.read_bytes() == "Car 0 0 ü\n".encode()
    assert synced == [False, True]  # the file, then its folder (the rename)
    atomic_write_bytes(target, b"\x00\x01")
    assert target.read_bytes() == b"\x00\x01" and _names(target.parent) == ["label.txt"]


@pytest.mark.parametrize("where", ["body", "fsync", "replace"])
def test_a_failed_atomic_write_leaves_the_old_file_and_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, where: str
) -> None:
    target = tmp_path / "model.pt"
    target.write_bytes(b"old")
    if where == "fsync":
        monkeypatch.setattr(os, "fsync", _enospc)
    if where == "replace":
        monkeypatch.setattr(os, "replace", _enospc)
    expected = RuntimeError if where == "body" else OSError
    with pytest.raises(expected), atomic_file(target) as handle:
        handle.write(b"new, but only half")
        if where == "body":
            raise RuntimeError("the serialiser failed")
    monkeypatch.undo()
    assert target.read_bytes() == b"old"
    assert _names(tmp_path) == ["model.pt"]


def test_a_failed_first_write_creates_nothing(tmp_path: Path) -> None:
    with pytest.raises(KeyboardInterrupt), atomic_file(tmp_path / "new.txt", binary=False) as fh:
        fh.write("partial")
        raise KeyboardInterrupt
    assert _names(tmp_path) == []


def test_link_or_copy_links_and_falls_back_to_a_copy(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    src = tmp_path / "lidar.bin"
    src.write_bytes(b"points")
    linked = tmp_path / "a" / "00001.bin"
    link_or_copy(src, linked)
    assert linked.stat().st_ino == src.stat().st_ino
    monkeypatch.setattr(os, "link", _exdev)
    copied = tmp_path / "b" / "00001.bin"
    copied.parent.mkdir()
    copied.write_bytes(b"an older sample")
    link_or_copy(src, copied)
    assert copied.read_bytes() == b"points" and copied.stat().st_ino != src.stat().st_ino
    assert _names(copied.parent) == ["00001.bin"]


def test_link_or_copy_onto_the_same_file_does_nothing(tmp_path: Path) -> None:
    src = tmp_path / "lidar.bin"
    src.write_bytes(b"points")
    other = tmp_path / "00001.bin"
    link_or_copy(src, other)
    link_or_copy(src, other)  # already a link to it: a rename would do nothing, leaving a temporary
    link_or_copy(src, src)
    assert _names(tmp_path) == ["00001.bin", "lidar.bin"]
    assert other.stat().st_ino == src.stat().st_ino and src.read_bytes() == b"points"


def test_replace_files_changes_nothing_when_a_temporary_cannot_be_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    targets = [(tmp_path / "lidar" / "p.txt", "new 1\n"), (tmp_path / "radar" / "p.txt", "new 2\n")]
    for path, _ in targets:
        path.parent.mkdir()
        path.write_text("old\n")
    calls = {"n": 0}
    real = os.fsync

    def fsync(fd: int) -> None:  # the second file's fsync hits a full disk
        calls["n"] += 1
        if calls["n"] == 2:
            _enospc()
        real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    with pytest.raises(OSError, match="No space"):
        replace_files(targets)
    monkeypatch.undo()
    for path, _ in targets:
        assert path.read_text() == "old\n" and _names(path.parent) == ["p.txt"]
    replace_files(targets)
    assert [path.read_text() for path, _ in targets] == ["new 1\n", "new 2\n"]
    assert _names(tmp_path / "lidar") == ["p.txt"]


# ------------------------------------------------------------------------------------------ JSONL


def test_a_torn_last_line_is_reported_terminated_and_cut(tmp_path: Path) -> None:
    log_path = tmp_path / "manifest.jsonl"
    append_json_line(log_path, {"settings": 1})
    append_json_line(log_path, {"world": 0})
    whole = log_path.read_bytes()
    with open(log_path, "ab") as handle:
        handle.write(b'{"world": 1, "fi')  # a kill in the middle of an append
    log = read_json_lines(log_path)
    assert [value for _, value in log.entries] == [{"settings": 1}, {"world": 0}]
    assert [lineno for lineno, _ in log.unreadable] == [3] and log.torn_tail
    assert log.last_offset == len(whole)
    drop_torn_tail(log)
    assert log_path.read_bytes() == whole
    drop_torn_tail(read_json_lines(log_path))  # nothing torn: nothing cut
    assert log_path.read_bytes() == whole


def test_an_append_after_a_torn_line_stands_alone(tmp_path: Path) -> None:
    log_path = tmp_path / "manifest.jsonl"
    log_path.write_bytes(b'{"op": 1}\n{"op": 2, "ac')
    append_json_line(log_path, {"op": 3})
    log = read_json_lines(log_path)
    assert [value["op"] for _, value in log.entries] == [1, 3]
    assert [lineno for lineno, _ in log.unreadable] == [2] and not log.torn_tail
    assert log_path.read_bytes().endswith(b'\n{"op": 3}\n')


def test_a_failed_append_is_truncated_back(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    log_path = tmp_path / "manifest.jsonl"
    append_line(log_path, '{"op": 1}')
    before = log_path.read_bytes()
    real = os.write

    def half_then_full(fd: int, data) -> int:
        real(fd, bytes(data)[:5])
        _enospc()

    monkeypatch.setattr(os, "write", half_then_full)
    with pytest.raises(OSError, match="No space"):
        append_line(log_path, '{"op": 2}')
    monkeypatch.undo()
    assert log_path.read_bytes() == before


def test_unreadable_lines_are_reported_never_fatal(tmp_path: Path) -> None:
    log_path = tmp_path / "log.jsonl"
    log_path.write_bytes(b'{"a": 1}\n\n  \n[1, 2]\n\xff\xfe{\n{"a": "x"}\n{"a": 3}\n')

    def parse(value: object) -> int:
        return int(value["a"])  # a list: TypeError; "x": ValueError

    log = read_json_lines(log_path, parse)
    assert log.entries == ((1, 1), (7, 3))
    assert [lineno for lineno, _ in log.unreadable] == [4, 5, 6]
    assert log.last_line == 7 and not log.torn_tail
    assert read_json_lines(tmp_path / "missing.jsonl").entries == ()


def test_every_writer_of_the_project_uses_this_module() -> None:
    """No other module of scenes/, annotate/, app/, model/, bench/, tools/ or launch.py renames files
    itself or names temporaries."""
    root = Path(durable.__file__).parents[2]
    offenders = []
    packages = ("scenes", "annotate", "app", "model", "bench", "tools")
    files = [p for package in packages for p in sorted((root / package).rglob("*.py"))]
    for path in [*files, root / "launch.py"]:
        if path.name == "durable.py":
            continue
        text = path.read_text()
        for needle in ("os.replace(", "os.fsync(", ".tmp", "mkstemp"):
            if needle in text:
                offenders.append(f"{path.relative_to(root)}: {needle}")
    # The journal's move to unresolved/ is a rename of a whole file, not a write.
    assert offenders == ["annotate/journal.py: os.replace("]
