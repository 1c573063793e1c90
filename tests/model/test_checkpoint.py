"""Checkpoints: round trip, small size, atomic writes, and clear errors."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from model import build_model
from model.checkpoint import (
    FORMAT_VERSION,
    CheckpointError,
    load_checkpoint,
    read_checkpoint,
    save_checkpoint,
)
from model.checkpoint_meta import CheckpointMeta, is_machine_path, portable_path
from model.core.grid import BevGrid
from model.tpcnet import TPCNet
from tests.paths import REPO

COARSE = BevGrid(0.0, 51.2, -25.6, 25.6, 1.28)
META = {"data": "synthetic v1, 64 frames, seed 0", "metric": {"mAP_3d_R11": 0.123}, "epoch": 3}


def _inputs() -> tuple[list[np.ndarray], list[np.ndarray], list[str]]:
    rng = np.random.default_rng(0)
    lidar = np.column_stack(
        [
            rng.uniform(0, 51, 500),
            rng.uniform(-25, 25, 500),
            rng.uniform(-2, 1, 500),
            rng.uniform(0, 255, 500),
        ]
    ).astype(np.float32)
    radar = np.column_stack(
        [rng.uniform(0, 51, 50), rng.uniform(-25, 25, 50), rng.uniform(-2, 1, (50, 5))]
    ).astype(np.float32)
    return [lidar], [radar], ["the car ahead"]


@pytest.fixture(scope="module")
def trained() -> TPCNet:
    torch.manual_seed(0)
    model = build_model("small", pillars__grid=COARSE, text_encoder="gru")
    with torch.no_grad():  # non-default BatchNorm statistics, so that buffers must round-trip
        model.train()(*_inputs())
    return model.eval()


def test_round_trip(trained: TPCNet, tmp_path: Path) -> None:
    path = save_checkpoint(tmp_path / "sub" / "model.pt", trained, **META)
    assert path.is_file()
    assert [p.name for p in path.parent.iterdir()] == ["model.pt"]  # no temp file left behind
    loaded = load_checkpoint(path)
    assert loaded.cfg == trained.cfg and not loaded.training
    assert loaded.checkpoint_metadata == CheckpointMeta.from_dict(META)
    assert read_checkpoint(path)["metadata"] == META
    with torch.no_grad():
        a, b = trained(*_inputs()), loaded(*_inputs())
    torch.testing.assert_close(a.heatmap, b.heatmap)
    torch.testing.assert_close(a.regression, b.regression)
    # Overwriting keeps one file.
    save_checkpoint(path, loaded, **{**META, "epoch": 4})
    assert read_checkpoint(path)["metadata"]["epoch"] == 4
    assert [p.name for p in path.parent.iterdir()] == ["model.pt"]


def test_a_failed_save_keeps_the_old_checkpoint(
    trained: TPCNet, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = save_checkpoint(tmp_path / "model.pt", trained, **META)
    before = path.read_bytes()

    def full_disk(obj: Any, handle: Any) -> None:
        handle.write(b"half a checkpoint")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(torch, "save", full_disk)
    with pytest.raises(OSError, match="No space"):
        save_checkpoint(path, trained, **{**META, "epoch": 9})
    assert path.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["model.pt"]


def test_frozen_text_encoder_is_not_stored(tmp_path: Path) -> None:
    model = build_model("small")
    path = save_checkpoint(tmp_path / "m.pt", model)
    payload = torch.load(path, weights_only=True)
    assert payload["format_version"] == FORMAT_VERSION
    assert not any(k.startswith("text_encoder.") for k in payload["state_dict"])
    trainable = sum(p.numel() for p in model.parameters())
    assert path.stat().st_size < 4 * trainable * 1.5 + 200_000  # float32 weights + buffers only
    assert path.stat().st_size < 10_000_000  # MiniLM alone would be ~90 MB


def _rewrite(path: Path, change: Any) -> None:
    payload = torch.load(path, weights_only=True)
    change(payload)
    torch.save(payload, path)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda p: p["config"]["fusion"].update(window=3), "fusion.window"),
        (lambda p: p["config"]["text_fusion"].pop("graph_k"), "text_fusion.graph_k"),
        (lambda p: p["config"]["fusion"].update(kind="concat"), "fusion.kind"),
        (lambda p: p["config"]["backbone"].update(channels=[32, 48]), "backbone.channels"),
        (lambda p: p.update(format_version=99), "format_version 99"),
        (lambda p: p["state_dict"].pop("head.shared.0.weight"), "head.shared.0.weight"),
        (lambda p: p["state_dict"].update(extra=torch.zeros(1)), "'extra'"),
        (
            lambda p: p["state_dict"].update({"head.shared.0.weight": torch.zeros(1, 1, 3, 3)}),
            "head.shared.0.weight",
        ),
    ],
)
def test_mismatch_errors_name_the_field(
    trained: TPCNet, tmp_path: Path, change: Any, message: str
) -> None:
    path = save_checkpoint(tmp_path / "m.pt", trained)
    _rewrite(path, change)
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(path)
    assert message in str(info.value) and str(path) in str(info.value)


def test_missing_and_corrupt_files(tmp_path: Path) -> None:
    missing = tmp_path / "nope.pt"
    with pytest.raises(CheckpointError, match="does not exist") as info:
        load_checkpoint(missing)
    assert str(missing) in str(info.value)
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes(b"\x00not a checkpoint" * 10)
    with pytest.raises(CheckpointError, match="corrupt") as info:
        load_checkpoint(corrupt)
    assert str(corrupt) in str(info.value)
    other = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(2)}, other)
    with pytest.raises(CheckpointError, match="not a talk2pc-tpcnet checkpoint"):
        load_checkpoint(other)


def test_metadata_must_be_plain_data(trained: TPCNet, tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="metadata"):
        save_checkpoint(tmp_path / "m.pt", trained, when=object())
    assert not list(tmp_path.iterdir())


def test_numpy_scalars_in_metadata_load_back_with_weights_only(tmp_path):
    import numpy as np

    from model import build_model
    from model.checkpoint import load_checkpoint, save_checkpoint

    path = save_checkpoint(
        tmp_path / "m.pt", build_model("small"), operating_threshold=np.float64(0.45)
    )
    meta = load_checkpoint(path).checkpoint_metadata
    assert meta.operating_threshold == 0.45 and type(meta.operating_threshold) is float


def test_checkpoint_meta_reads_and_writes_the_files_dict() -> None:
    from model import DEFAULT_CHECKPOINT, read_checkpoint

    shipped = read_checkpoint(DEFAULT_CHECKPOINT)["metadata"]
    meta = CheckpointMeta.from_dict(shipped)
    assert meta.to_dict() == shipped and list(meta.to_dict()) == list(shipped)
    assert meta.step == shipped["step"] and not meta.extra
    assert meta.operating_threshold == shipped.get("operating_threshold")
    other = CheckpointMeta.from_dict({"epoch": 4, "note": "kept"})  # an older or foreign dict
    assert other.epoch == 4 and other.step is None and other.extra == {"note": "kept"}
    assert other.to_dict() == {"epoch": 4, "note": "kept"}
    assert CheckpointMeta.of(object()) == CheckpointMeta()


SHIPPED = sorted((REPO / "checkpoints").glob("*.pt"))


def _strings(value: Any) -> list[str]:
    """Every string in plain data (keys and values)."""
    if isinstance(value, str):
        return [value]
    if isinstance(value, dict):
        return [s for k, v in value.items() for s in (*_strings(k), *_strings(v))]
    if isinstance(value, (list, tuple)):
        return [s for v in value for s in _strings(v)]
    return []


@pytest.mark.parametrize("path", SHIPPED, ids=[p.name for p in SHIPPED])
def test_shipped_checkpoints_hold_no_machine_paths(path: Path) -> None:
    """No string of a shipped checkpoint's metadata is an absolute path of the machine it was
    made on (``/work/...``, ``~...``, ``C:\\...``); it loads as a CheckpointMeta."""
    from model import read_checkpoint

    assert len(SHIPPED) >= 2
    metadata = read_checkpoint(path)["metadata"]
    found = [s for s in _strings(metadata) if is_machine_path(s)]
    assert not found, f"{path.name}: {found}"
    assert load_checkpoint(path).checkpoint_metadata == CheckpointMeta.from_dict(metadata)


def test_portable_paths_are_relative_to_the_working_folder_or_as_given(tmp_path: Path) -> None:
    base = tmp_path / "repo"
    (base / "data" / "x").mkdir(parents=True)
    assert portable_path(base / "data" / "x", base) == "data/x"
    assert portable_path("data/x", base) == "data/x"  # as the user gave it
    assert portable_path("/elsewhere/y", base) == "/elsewhere/y"  # outside: as given
    assert all(map(is_machine_path, ["/a", "~/a", "C:\\a", "D:/a", "\\\\host\\share\\a"]))
    assert not any(map(is_machine_path, ["data/a", "a:b", "runs/x", "small"]))
    meta = CheckpointMeta(
        data={"root": str(base / "data" / "x"), "roots": [str(base / "data" / "x")]},
        operating_threshold_source={"root": str(base / "data"), "split": "val"},
        train_config={"data": ["data/x"], "out": str(base / "runs" / "r"), "lr": 0.1},
        step=3,
    ).with_portable_paths(base)
    assert meta.data == {"root": "data/x", "roots": ["data/x"]}
    assert meta.operating_threshold_source == {"root": "data", "split": "val"}
    assert meta.train_config == {"data": ["data/x"], "out": "runs/r", "lr": 0.1}
    assert meta.step == 3


def test_an_old_checkpoint_with_absolute_paths_and_a_dict_still_loads(
    trained: TPCNet, tmp_path: Path
) -> None:
    """A checkpoint written before (metadata a dict with this machine's absolute paths) loads;
    the model holds its metadata as a CheckpointMeta, paths as they were."""
    old = {"data": {"root": "/work/main/data/train", "train_samples": 4}, "step": 9}
    path = save_checkpoint(tmp_path / "old.pt", trained, **old)
    meta = load_checkpoint(path).checkpoint_metadata
    assert isinstance(meta, CheckpointMeta) and meta.step == 9
    assert meta.data == old["data"] and meta.to_dict() == old
