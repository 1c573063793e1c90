"""Issue 50: ``scenes.export_nuscenes`` never deletes what it did not write. It writes only into a
new or empty folder or an earlier export of its own (recognised by its marker), refuses any other
non-empty folder and any folder that is, lies in or contains the source with one line, keeps
foreign files in its own folder, and a failed or killed export leaves nothing that blocks the
next one (scenes.utils.owned). A tiny synthetic source without camera (about 1 s)."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pytest

from scenes.export_nuscenes import WRITER, export, main
from scenes.utils.owned import MARKER, FolderError


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from scenes.synth.generate import SynthSettings, generate_root

    out = tmp_path_factory.mktemp("r5-export") / "synth"
    generate_root(out, 8, SynthSettings(seed=4, prompts_per_world=4, camera=None))
    return out


def _tree(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` (relative path -> content hash)."""
    return {
        p.relative_to(folder).as_posix(): hashlib.md5(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def _user_folder(path: Path) -> Path:
    """A folder of the user's: another release's version folder, notes, command files."""
    (path / "v1.0-mini").mkdir(parents=True)
    (path / "v1.0-mini" / "sample.json").write_text("[]\n")
    (path / "notes.txt").write_text("my notes\n")
    (path / "commands").mkdir()
    (path / "commands" / "train_commands.json").write_text('{"mine": true}\n')
    return path


def test_a_foreign_folder_is_refused_and_kept(source: Path, tmp_path: Path, capsys) -> None:
    out = _user_folder(tmp_path / "user")
    before = _tree(out)
    with pytest.raises(FolderError, match=f"{out}: is not empty and was not written by"):
        export(source, out)
    assert _tree(out) == before
    assert main(["--source", str(source), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {out}: ") and "notes.txt" in err[0]
    assert _tree(out) == before
    assert [p.name for p in tmp_path.iterdir()] == ["user"]  # no staging left beside it


@pytest.mark.parametrize("where", ["inside", "equal", "containing"])
def test_an_output_overlapping_the_source_is_refused(
    source: Path, tmp_path: Path, where: str
) -> None:
    import shutil

    src = tmp_path / "data" / "synth"
    shutil.copytree(source, src)
    out = {"inside": src / "nusc", "equal": src, "containing": src.parent}[where]
    before = _tree(tmp_path)
    relation = {"inside": "lies inside", "equal": "is", "containing": "contains"}[where]
    with pytest.raises(FolderError, match=f"{relation} the source root"):
        export(src, out)
    assert _tree(tmp_path) == before


def test_an_earlier_export_is_replaced_and_foreign_files_kept(source: Path, tmp_path: Path) -> None:
    out = tmp_path / "nusc"
    export(source, out, seed=1)
    marker = json.loads((out / MARKER).read_text())
    assert marker["writer"] == WRITER and "v1.0-trainval/sample.json" in marker["files"]
    (out / "notes.txt").write_text("mine\n")
    (out / "commands" / "mine_commands.json").write_text("{}\n")
    (out / "samples" / "extra").mkdir()
    (out / "samples" / "extra" / "x.bin").write_bytes(b"x")
    ego = (out / "v1.0-trainval" / "ego_pose.json").read_text()
    export(source, out, seed=2)  # another seed: other poses
    assert (out / "v1.0-trainval" / "ego_pose.json").read_text() != ego
    assert (out / "notes.txt").read_text() == "mine\n"
    assert (out / "commands" / "mine_commands.json").read_text() == "{}\n"
    assert (out / "samples" / "extra" / "x.bin").read_bytes() == b"x"
    export(source, out, version="v1.0-mini")  # the earlier version folder was ours: removed
    assert not (out / "v1.0-trainval").exists() and (out / "v1.0-mini" / "sample.json").is_file()
    assert (out / "notes.txt").is_file() and (out / "samples" / "extra" / "x.bin").is_file()
    files = json.loads((out / MARKER).read_text())["files"]
    assert "notes.txt" not in files and not any(f.startswith("v1.0-trainval/") for f in files)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nusc"]


def test_a_foreign_file_in_the_way_refuses_the_install(source: Path, tmp_path: Path) -> None:
    out = tmp_path / "nusc"
    export(source, out)
    (out / "v1.0-mini").mkdir()
    (out / "v1.0-mini" / "sample.json").write_text("mine\n")
    before = _tree(out)
    with pytest.raises(FolderError, match=r"v1\.0-mini/sample\.json: was not written by"):
        export(source, out, version="v1.0-mini")
    assert _tree(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nusc"]


def test_a_failed_export_leaves_nothing_that_blocks_the_next(
    source: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import scenes.export_nuscenes as module

    real = module.export_frames

    def failing(frames, out, **kwargs):
        (Path(out) / "v1.0-trainval").mkdir(parents=True)
        (Path(out) / "v1.0-trainval" / "scene.json").write_text("[")
        raise OSError(28, "No space left on device")

    out = tmp_path / "nusc"
    monkeypatch.setattr(module, "export_frames", failing)
    with pytest.raises(OSError, match="No space"):
        export(source, out)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(module, "export_frames", real)
    export(source, out)
    before = _tree(out)
    monkeypatch.setattr(module, "export_frames", failing)
    with pytest.raises(OSError, match="No space"):
        export(source, out, seed=9)
    assert _tree(out) == before and [p.name for p in tmp_path.iterdir()] == ["nusc"]


def test_a_killed_exports_staging_is_removed_by_the_next(source: Path, tmp_path: Path) -> None:
    dead = int(Path("/proc/sys/kernel/pid_max").read_text()) + 1  # no process has it
    stale = tmp_path / f".nusc.{dead}-deadbeef.staging"
    (stale / "samples").mkdir(parents=True)
    (stale / "samples" / "a.bin").write_bytes(b"a")
    (stale / MARKER).write_text(json.dumps({"writer": WRITER, "staging": True, "pid": dead}))
    alive = tmp_path / f".nusc.{os.getpid()}-0000beef.staging"  # a running export's: kept
    alive.mkdir()
    (alive / MARKER).write_text(json.dumps({"writer": WRITER, "staging": True, "pid": os.getpid()}))
    export(source, tmp_path / "nusc")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["nusc", alive.name])


def test_an_empty_folder_is_written_into(source: Path, tmp_path: Path) -> None:
    out = tmp_path / "empty"
    out.mkdir()
    export(source, out)
    assert json.loads((out / MARKER).read_text())["writer"] == WRITER
    assert (out / "v1.0-trainval" / "sample.json").is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["empty"]


def test_a_marker_naming_files_outside_its_folder_is_no_marker(
    source: Path, tmp_path: Path
) -> None:
    """A hand-edited (or forged) marker listing ``../x`` or an absolute path: the folder is not
    recognised as an export's, so nothing outside it (nor in it) is removed."""
    out = tmp_path / "nusc"
    export(source, out)
    victim = tmp_path / "victim.txt"
    for name in ("../victim.txt", str(victim), "a/../../victim.txt", ""):
        victim.write_text("mine\n")
        marker = json.loads((out / MARKER).read_text())
        marker["files"] = [*marker["files"], name]
        (out / MARKER).write_text(json.dumps(marker))
        before = _tree(out)
        with pytest.raises(FolderError, match="was not written by"):
            export(source, out, seed=5)
        assert victim.read_text() == "mine\n" and _tree(out) == before, name
        marker["files"].remove(name)
        (out / MARKER).write_text(json.dumps(marker))


def test_nothing_is_written_or_removed_through_a_link_in_the_output(
    source: Path, tmp_path: Path
) -> None:
    """A folder of an earlier export replaced by a link to the user's folder: the export does
    not write through it (refused, nothing changed), nor remove the files behind it."""
    out = tmp_path / "nusc"
    export(source, out)
    mine = tmp_path / "mine"
    (out / "maps").rename(mine)
    (out / "maps").symlink_to(mine)
    before, theirs = _tree(out), _tree(mine)
    with pytest.raises(FolderError, match=r"outside .* once links are resolved"):
        export(source, out, seed=5)
    assert _tree(out) == before and _tree(mine) == theirs
    (out / "maps").unlink()
    (out / "maps").mkdir()
    (out / "maps" / "elsewhere").symlink_to(mine, target_is_directory=True)
    marker = json.loads((out / MARKER).read_text())
    marker["files"] += [f"maps/elsewhere/{p.name}" for p in mine.iterdir()]
    (out / MARKER).write_text(json.dumps(marker))  # as if an export had written them
    export(source, out, seed=5)  # it writes no file there now: the files behind the link stay
    assert _tree(mine) == theirs


def test_the_current_folder_and_a_link_to_an_empty_folder(
    source: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--out .`` (an empty working folder) is written into in place (the same folder, nothing
    staged inside it), and ``--out LINK`` to an empty folder writes into that folder, staged
    beside it, the link kept."""
    here = tmp_path / "here"
    here.mkdir()
    inode = here.stat().st_ino
    monkeypatch.chdir(here)
    assert main(["--source", str(source), "--out", "."]) == 0
    assert here.stat().st_ino == inode and (here / "v1.0-trainval" / "sample.json").is_file()
    assert not [p for p in here.iterdir() if p.name.endswith(".staging")]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["here"]
    target = tmp_path / "disk" / "target"
    target.mkdir(parents=True)
    link = tmp_path / "link"
    link.symlink_to(target)
    export(source, link)
    assert link.is_symlink() and (target / "v1.0-trainval" / "sample.json").is_file()
    assert [p.name for p in target.parent.iterdir()] == ["target"]
    export(source, link, seed=3)  # an earlier export through the link: replaced
    assert json.loads((target / MARKER).read_text())["writer"] == WRITER
