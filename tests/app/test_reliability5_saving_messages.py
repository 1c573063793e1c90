"""Issue 50's smaller items on the Annotate tab of a nuScenes root: a pairs file holding a command
that does not resolve against the served root is one line in the tab and the log (no traceback)
and the app keeps serving; without ``--pairs`` the console, the status line and the checks say one
thing: nothing is saved (no "Pairs are saved into ...", no "Ready to save"). The tiny exported
root of the ``nuscenes_root`` fixture and the untrained small model."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest

from annotate import Draft
from annotate.editor import History
from annotate.validation import ValidationReport
from app.annotate_tab.formatting import checks_markdown, status_markdown
from app.annotate_tab.hub import AnnotationHub
from app.serving.served import serve_root
from app.text import md_text
from scenes.datasets.source import NuScenesSource


def test_status_and_checks_say_nothing_is_saved_when_saving_is_unavailable() -> None:
    draft = Draft().set_prompt("stop behind it").add_box(np.array([10, 0, 0, 4, 2, 1.5, 0]), "Car")
    status = status_markdown(
        draft,
        History(),
        "sample-1",
        True,
        False,
        unavailable="restart with --pairs DIR",
        saving_to=(Path("/data/nusc-talk2car"), "Talk2Car command files"),
    )
    assert "Saving is unavailable" in status and "Pairs are saved into" not in status
    checks = checks_markdown(ValidationReport(), saving=False)
    assert "Ready to save" not in checks and "saving is unavailable" in checks
    assert "Ready to save" in checks_markdown(ValidationReport())
    shown = status_markdown(draft, History(), "s", True, False, saving_to=(Path("/p"), "x"))
    assert "Pairs are saved into" in shown


def test_the_status_says_what_the_pairs_folder_holds(nuscenes_root: Path, tmp_path: Path) -> None:
    """On a nuScenes root pairs are Talk2Car command files, not a Talk2Radar root."""
    source = NuScenesSource(nuscenes_root, nuscenes_root / "commands")
    served = serve_root(source, pairs=tmp_path / "pairs")
    said = served.pairs_described()
    assert "Talk2Car command files" in said and "Talk2Radar" not in said
    draft = Draft().set_prompt("stop behind it")
    shown = status_markdown(draft, History(), "s", True, False, saving_to=(tmp_path, said))
    assert "Talk2Car command files" in shown and "Talk2Radar root" not in shown


def test_the_console_line_says_where_pairs_go_or_that_none_are_saved(
    nuscenes_root: Path, tmp_path: Path
) -> None:
    source = NuScenesSource(nuscenes_root, nuscenes_root / "commands")
    unnamed = AnnotationHub(serve_root(source))
    line = unnamed.saving_line()
    assert line.startswith("Annotation does not save pairs: ") and "--pairs" in line
    assert "saves pairs into" not in line and "\n" not in line
    named = AnnotationHub(serve_root(source, pairs=tmp_path / "pairs"))
    assert named.saving_line() == f"Annotation saves pairs into {tmp_path / 'pairs'}"
    assert not (tmp_path / "pairs").exists()


@pytest.fixture()
def bad_pairs(nuscenes_root: Path, tmp_path: Path) -> Path:
    """A pairs folder whose train file holds one command that does not resolve (its sample
    token names no CAM_FRONT sample_data of the root)."""
    data = json.loads((nuscenes_root / "commands" / "train_commands.json").read_text())
    data["commands"] = data["commands"][:1]
    data["commands"][0]["sample_token"] = "f" * 32
    (tmp_path / "pairs" / "commands").mkdir(parents=True)
    (tmp_path / "pairs" / "commands" / "train_commands.json").write_text(json.dumps(data))
    return tmp_path / "pairs"


def test_an_unresolvable_pairs_file_is_a_notice_and_the_tab_builds(
    nuscenes_root: Path, bad_pairs: Path, serve_app, untrained_model, ws_client, torch_threads,
    caplog: pytest.LogCaptureFixture,
) -> None:  # fmt: skip
    caplog.set_level(logging.WARNING)
    model = untrained_model("referent", text_encoder="gru", head__score_threshold=0.0)
    config = {"talk2car": nuscenes_root / "commands", "pairs_root": bad_pairs, "warm_up": False}
    with torch_threads(1), serve_app(nuscenes_root, model, split="train", **config) as app:
        before = set(app.sessions)
        client = ws_client(app.port)
        try:
            client.pump_until(
                lambda: (
                    "Save pair" in client.gui
                    and any("cannot be listed" in m for m in client.markdown.values())
                ),
                20,
                "the Annotate tab with its notice",
            )
            session = app.sessions[(set(app.sessions) - before).pop()]
            panel = next(p for p in app.annotations.panels() if p.session is session)
            assert panel.w.pairs.content.startswith("**Saved pairs cannot be listed:**")
            assert md_text("train_commands.json: 1 command(s) do not resolve") in (
                panel.w.pairs.content
            )
            assert "\n" not in panel.w.pairs.content
        finally:
            client.close()
    failed = [r for r in caplog.records if r.exc_info or "failed to build" in r.getMessage()]
    assert not failed, [r.getMessage() for r in failed]
    notices = [r.getMessage() for r in caplog.records if "cannot be listed" in r.getMessage()]
    assert notices and all("\n" not in n for n in notices)
