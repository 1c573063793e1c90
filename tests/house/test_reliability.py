"""Command lines given an output they cannot write: one line ``error: ...`` naming it, exit code 2,
no traceback (issue 11). ``launch.py``: tests/launch/test_launch.py; ``model.evaluate``:
tests/model/evaluation/test_evaluate_cli.py."""

from __future__ import annotations

import errno
from pathlib import Path

import pytest

from scenes.synth import generate as synth


def _error_line(capsys: pytest.CaptureFixture) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


def test_synth_out_on_a_file(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "a-file"
    out.write_text("not a folder")
    assert synth.main(["--out", str(out), "--frames", "2", "--quiet"]) == 2
    assert str(out) in _error_line(capsys)


def test_synth_out_in_a_read_only_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / "read-only"
    folder.mkdir()
    real_mkdir = Path.mkdir

    def mkdir(self: Path, *args, **kwargs) -> None:  # what a read-only folder says (even to root)
        if self.is_relative_to(folder):
            raise PermissionError(errno.EACCES, "Permission denied", str(self))
        real_mkdir(self, *args, **kwargs)

    monkeypatch.setattr(Path, "mkdir", mkdir)
    out = folder / "root"
    assert synth.main(["--out", str(out), "--frames", "2", "--quiet"]) == 2
    line = _error_line(capsys)
    assert str(out) in line and "Permission denied" in line
