"""Issue 50: the Talk2Car pairs store never writes into the served release or the ``--talk2car``
folder (a ``--pairs`` folder whose ``commands/`` lies there is refused with one line, before
anything is written), and a save or a deletion keeps every key it did not write: a command's keys
beyond the release's eleven and top-level keys such as ``version``, the other commands' records
as they were. The tiny exported root of the ``nuscenes_root`` fixture, copied."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from annotate import Draft, StoreError
from annotate.talk2car import Talk2CarStore
from app.serving.served import serve_root
from app.serving.served_nuscenes import NuScenesServed
from scenes.datasets.source import NuScenesSource
from scenes.frame import RootError
from scenes.nuscenes.classes import model_class


@pytest.fixture()
def release(nuscenes_root: Path, tmp_path: Path) -> Path:
    """A copy of the tiny release (read-only fixture) to try writes on."""
    out = tmp_path / "NUSC"
    shutil.copytree(nuscenes_root, out)
    return out


def _tree(folder: Path) -> dict[str, str]:
    return {
        p.relative_to(folder).as_posix(): hashlib.md5(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.mark.parametrize("pairs", ["root", "inside"])
def test_pairs_into_the_release_are_refused(release: Path, pairs: str) -> None:
    before = _tree(release)
    source = NuScenesSource(release, release / "commands")
    folder = release if pairs == "root" else release / "my-pairs"
    with pytest.raises(RootError, match=f"--pairs: pairs folder {folder}: .*never written") as e:
        serve_root(source, pairs=folder)
    assert "\n" not in str(e.value)
    with pytest.raises(StoreError, match="inside the served nuScenes root"):
        Talk2CarStore(folder, source.nuscenes)
    assert _tree(release) == before


def test_pairs_into_the_talk2car_folder_are_refused(release: Path, tmp_path: Path) -> None:
    t2c = tmp_path / "t2c"
    shutil.copytree(release / "commands", t2c / "commands")
    before = _tree(t2c)
    source = NuScenesSource(release, t2c / "commands")
    for folder in (t2c, t2c / "commands"):
        with pytest.raises(RootError, match=f"pairs folder {folder}: .*the --talk2car folder"):
            serve_root(source, pairs=folder)
    served = serve_root(source, pairs=tmp_path / "pairs")  # apart from both: accepted
    assert isinstance(served, NuScenesServed) and served.named
    assert _tree(t2c) == before


def _draft_on(source: NuScenesSource) -> tuple[Draft, object]:
    root = source.nuscenes
    for token in root.samples:
        boxes, categories, attributes = root.annotation_boxes(token)
        for box, cat, att in zip(boxes, categories, attributes, strict=True):
            cls = model_class(cat, att)
            if cls is not None and 8 < box[0] < 40 and abs(box[1]) < 6:
                return Draft().set_prompt("stop next to that one").add_box(box, cls), token
    raise AssertionError("no referable annotation")


def test_a_save_keeps_every_key_it_did_not_write(release: Path, tmp_path: Path) -> None:
    source = NuScenesSource(release, release / "commands")
    pairs = tmp_path / "pairs"
    original = json.loads((release / "commands" / "train_commands.json").read_text())
    assert original["commands"]
    data = {"version": "1.0", **original, "notes": {"by": "me"}}
    for i, c in enumerate(data["commands"]):
        c["ambiguous"] = i % 2 == 0
        c["extra"] = {"votes": [i, 1.5], "who": "ann"}
    (pairs / "commands").mkdir(parents=True)
    file = pairs / "commands" / "train_commands.json"
    file.write_text(json.dumps(data, indent=1) + "\n")
    served = serve_root(source, pairs=pairs)
    store = served.open_store()
    draft, token = _draft_on(source)
    sample = source.load(token)
    saved = store.save(draft, served.source_frame(sample), split="train")
    after = json.loads(file.read_text())
    assert list(after) == list(data) and after["version"] == "1.0"
    assert after["notes"] == {"by": "me"}
    assert after["commands"][:-1] == data["commands"]  # every key, every value, in order
    assert after["commands"][-1]["command_token"] == saved.sample_id
    # Deleting one command keeps the others' records and the file's keys.
    store.delete(data["commands"][0]["command_token"])
    again = json.loads(file.read_text())
    assert again["version"] == "1.0" and again["notes"] == {"by": "me"}
    assert again["commands"] == after["commands"][1:]
    np.testing.assert_equal(len(store.commands("train")), len(data["commands"]))


@pytest.mark.filterwarnings("ignore:.*byte-order mark")
def test_a_save_and_its_deletion_keep_the_files_bytes(release: Path, tmp_path: Path) -> None:
    """A pairs file in another layout (one line, as the release's files are; a byte-order mark,
    CRLF, numbers and escapes spelled its own way): a save keeps every byte of what it did not
    change, the new command follows the file's layout, and deleting it gives the file back."""
    source = NuScenesSource(release, release / "commands")
    pairs = tmp_path / "pairs"
    data = json.loads((release / "commands" / "train_commands.json").read_text())
    data = {"version": "1.0", **data}
    data["commands"][0]["extra"] = 1.5e-05
    text = json.dumps(data, separators=(",", ":"), ensure_ascii=False)
    text = text.replace("1.5e-05", "1.50E-5", 1).replace('"1.0"', '"1\\u002e0"', 1)
    (pairs / "commands").mkdir(parents=True)
    file = pairs / "commands" / "train_commands.json"
    original = b"\xef\xbb\xbf" + text.encode("utf-8") + b"\r\n"
    file.write_bytes(original)
    served = serve_root(source, pairs=pairs)
    store = served.open_store()
    draft, token = _draft_on(source)
    saved = store.save(draft, served.source_frame(source.load(token)), split="train")
    after = file.read_bytes()
    cut = original.rindex(b"]")  # the end of the commands list
    assert after.startswith(original[:cut]) and after.endswith(original[cut:])
    added = after[cut : len(after) - len(original) + cut]
    assert b"\n" not in added and saved.sample_id.encode() in added  # one line, as the file
    assert json.loads(after.decode("utf-8-sig"))["commands"][:-1] == data["commands"]
    store.delete(saved.sample_id)
    assert file.read_bytes() == original


def test_splice_keeps_the_stores_own_layout_and_falls_back() -> None:
    """A file the store wrote (indent 1) edited by a splice is the file a full rewrite gives;
    text that cannot be spliced (not an object, NaN, repeated keys) gives None: written whole."""
    from scenes.utils.json_splice import splice_object

    old = {"scene_tokens": ["a"], "commands": [{"command": "x", "n": 1.5}], "v": "1"}
    text = json.dumps(old, indent=1) + "\n"
    for new in (
        {**old, "scene_tokens": ["a", "b"], "commands": [*old["commands"], {"command": "y"}]},
        {**old, "commands": []},
        {**old, "extra": {"k": [1, 2]}},
        {"scene_tokens": [], "commands": [{"command": "z"}]},
    ):
        assert splice_object(text, new) == json.dumps(new, indent=1) + "\n"
    empty = json.dumps({"scene_tokens": [], "commands": []}, indent=1) + "\n"
    assert splice_object(empty, old) == text
    assert splice_object("[1]", old) is None
    assert splice_object('{"a": NaN}', {"a": float("nan"), "b": 1}) is None
    assert splice_object('{"a": 1, "a": 2}', {"a": 2, "b": 3}) is None
