"""Sentence-first pairs on labelled frames against the click-and-fit flow, in a real browser
(issue 19.2): clicks, keystrokes and seconds per pair on the same frames.

The frames: a synthetic root exported as the real releases come (``scenes.export_real``: a
Talk2Radar tree with one prompt per frame and its referents, and a View-of-Delft tree labelling
every object), served with the shipped referent-path checkpoint, without labels for the
click-and-fit flow (how pairs are made where no labels exist) and with ``scene_labels`` = the
View-of-Delft tree for the sentence-first flow. Each frame's own prompt is the sentence to annotate and its ``label_2`` the
referents the pair must get. Headless Chromium makes each pair twice, as a person would:

- **click and fit** (no labels needed): for each referent a ground click on it and F (*Fit to
  points*), then P, the sentence, Enter;
- **sentence first**: P, the sentence; the referent stage picks the referents among the labelled
  boxes while the sentence is read back; a click on each box it got wrong (a missing referent
  is clicked in, a wrong one out); Enter.

Typed characters are counted apart; moving to the next frame is not counted (the same in both:
each pair starts with no field focused, as after a click on the scene's *Next*).
Seconds run from the first action to the saved pair, with the sentence typed at once (a
person's typing time comes on top, the same in both flows). Run as a script for the numbers of
docs/ANNOTATION.md::

    python -m tests.app.browser.test_annotation_throughput --frames 6 --seed 5
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from tests.browser_helpers import (
    CHROMIUM_ARGS,
    PAGE_SIZE,
    REPO,
    find_chromium,
    open_annotate,
    pixel_of,
    poll,
)

TIMEOUT = 90.0
VIEWPORT = {"width": 1400, "height": 860}
CLICKABLE = (610.0, 40.0, 980.0, 820.0)
"""Page pixels (x0, y0, x1, y1) a click may land on: the control panel covers the right, the
camera panel the bottom left."""


@dataclass(frozen=True)
class PairRun:
    """One pair made in the browser."""

    flow: str
    sample_id: str
    clicks: int
    keys: int
    chars: int
    seconds: float
    exact: bool
    """The saved boxes are the referents (labelled boxes: exactly; fitted: each referent
    within 0.5 m of a box of its class, as many boxes as referents)."""


def make_roots(out: Path, frames: int, seed: int) -> tuple[Path, Path]:
    """A synthetic root of ``2 * frames`` test frames (one prompt each) exported as the releases
    come: ``(t2r, vod)``."""
    from scenes.export_real import export
    from scenes.synth.camera import CameraConfig
    from scenes.synth.generate import SynthSettings, generate_root

    camera = CameraConfig(image_scale=0.25, ray_step=4)
    settings = SynthSettings(seed=seed, camera=camera)
    generate_root(out / "synth", 4 * frames, settings, split_fractions=(0.0, 0.0, 1.0))
    export(out / "synth", out / "t2r", out / "vod", splits=["test"])
    return out / "t2r", out / "vod"


def _overview(panel) -> None:
    """A high view of the annotated range, shifted so that the objects ahead appear between
    the camera panel and the control panel."""
    from app.view.scene_view import CameraPose, apply_pose

    ground = panel.frame.ground_z
    apply_pose(
        panel.session.client.camera, CameraPose((21.0, 8.0, ground + 62.0), (22.0, 8.0, ground))
    )


def _clickable(camera, boxes: np.ndarray, ground: float) -> bool:
    for box in boxes:
        x, y = pixel_of(camera, (box[0], box[1], ground), PAGE_SIZE)
        if not (CLICKABLE[0] <= x <= CLICKABLE[2] and CLICKABLE[1] <= y <= CLICKABLE[3]):
            return False
    return True


def _matches(saved: np.ndarray, classes: tuple[str, ...], truth, exact: bool) -> bool:
    if len(saved) != len(truth.boxes):
        return False
    for box, cls in zip(truth.boxes, truth.classes, strict=True):
        same = [i for i, c in enumerate(classes) if c == cls]
        if not same:
            return False
        dist = (
            np.abs(saved[same] - box).max(axis=1)
            if exact
            else np.hypot(*(saved[same, :2] - box[:2]).T)
        )
        if dist.min() > (1e-4 if exact else 0.5):
            return False
    return True


def drive(app, chromium: str, flow: str, indices, count: int) -> tuple[list[PairRun], list[int]]:
    """Make one pair per frame with ``flow`` (``"click and fit"`` or ``"sentence first"``) on
    the first ``count`` of the frames ``indices`` whose referents (one or two) a click can
    reach in the overview; returns the pairs and the frames used."""
    from playwright.sync_api import sync_playwright

    from scenes.talk2radar.root import Talk2RadarRoot

    store = app.annotations.store
    runs, used = [], []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport=VIEWPORT)
            panel = open_annotate(page, app, TIMEOUT)
            # The served root's ground truth is the pair's answer: hidden (its labels would
            # also catch the clicks meant for the ground).
            panel.session.query.show_gt.value = False
            notes = []
            notify = panel.notify
            panel.notify = lambda *a, **k: (
                notes.append(a[0]),
                notify(*a, **k),
            )
            keys = page.keyboard
            for index in indices:
                if len(used) == count:
                    break
                app.go_to(index)
                sid = app.frames.ids[index]
                poll(lambda s=sid: panel.frame.sample.sample_id == s, TIMEOUT, "the frame")
                truth = panel.frame.sample
                if not 1 <= len(truth.boxes) <= 2:
                    continue
                ground = panel.frame.ground_z
                camera = panel.session.client.camera
                stamp = camera.update_timestamp
                _overview(panel)
                page.wait_for_timeout(500)
                poll(  # the browser reported the new view (its orientation with it)
                    lambda c=camera, t=stamp: c.update_timestamp > t and c.position[2] > 40.0,
                    TIMEOUT,
                    "the view",
                )
                if not _clickable(camera, truth.boxes, ground):
                    continue
                used.append(index)
                # As after a click on the next frame's button (not counted: the same in both).
                page.evaluate("() => document.activeElement && document.activeElement.blur()")
                before = len(store.pairs())
                clicks = presses = 0
                start = time.perf_counter()
                if flow == "click and fit":
                    for k, (box, cls) in enumerate(zip(truth.boxes, truth.classes, strict=True)):
                        if panel.w.cls.value != cls:
                            keys.press("123"[("Car", "Pedestrian", "Cyclist").index(cls)])
                            presses += 1
                            poll(lambda c=cls: panel.w.cls.value == c, TIMEOUT, "the class")
                        n = len(panel.draft.boxes)
                        notes.clear()
                        page.mouse.click(*pixel_of(camera, (box[0], box[1], ground), PAGE_SIZE))
                        clicks += 1
                        poll(lambda n=n: len(panel.draft.boxes) == n + 1 or notes, TIMEOUT, "box")
                        assert len(panel.draft.boxes) == n + 1, (k, box, notes)
                        notes.clear()
                        keys.press("f")
                        presses += 1
                        poll(
                            lambda: {"Box fitted", "Cannot fit the box"} & set(notes),
                            TIMEOUT,
                            "the fit",
                        )
                keys.press("p")
                keys.type(truth.prompt)
                presses += 1
                poll(lambda t=truth: panel.draft.prompt == t.prompt, TIMEOUT, "the sentence")
                fixes = 0
                if flow == "sentence first":
                    poll(lambda t=truth: panel_picked(panel, t.prompt), TIMEOUT, "the pick")
                    fixes = _correct_picks(page, panel, truth, camera, ground)
                    clicks += fixes
                if fixes:  # the clicks left the field: the save key
                    keys.press("Control+Shift+S")
                else:
                    keys.press("Enter")
                presses += 1
                poll(lambda b=before: len(store.pairs()) > b, TIMEOUT, "the save")
                seconds = time.perf_counter() - start
                saved_id = max(store.pairs(), key=lambda x: int(x.sample_id)).sample_id
                saved = Talk2RadarRoot(store.path).load(saved_id)
                exact = flow == "sentence first"
                right = _matches(saved.boxes, saved.classes, truth, exact)
                runs.append(
                    PairRun(
                        flow, truth.sample_id, clicks, presses, len(truth.prompt), seconds, right
                    )
                )
        finally:
            browser.close()
    return runs, used


def panel_picked(panel, prompt: str) -> bool:
    """Whether the referent picker has picked for ``prompt`` (the tab's state)."""
    return panel.referents_for() == prompt.strip()


def _correct_picks(page, panel, truth, camera, ground) -> int:
    """Click every labelled box the pick got wrong (in or out); returns the clicks."""
    wanted = [np.asarray(b) for b in truth.boxes]
    clicks = 0
    for item in list(panel.draft.boxes):
        box = np.asarray(item.box)
        if not any(np.abs(box - w).max() < 1e-4 for w in wanted):
            page.mouse.click(*pixel_of(camera, (box[0], box[1], ground), PAGE_SIZE))
            clicks += 1
    have = [np.asarray(b.box) for b in panel.draft.boxes]
    for box in wanted:
        if not any(np.abs(box - h).max() < 1e-4 for h in have):
            page.mouse.click(*pixel_of(camera, (box[0], box[1], ground), PAGE_SIZE))
            clicks += 1
    if clicks:
        page.wait_for_timeout(300)
    return clicks


def measure(frames: int, seed: int, chromium: str, out: Path) -> list[PairRun]:
    """Both flows on the same frames (see the module docstring)."""
    from model.checkpoint import load_checkpoint
    from tests.conftest import serve_app

    t2r, vod = make_roots(out, frames, seed)
    model = load_checkpoint(REPO / "checkpoints" / "tpcnet-small.pt")
    with serve_app(t2r, model, split="test", warm_up=False) as app:  # no labels: by hand
        first, indices = drive(app, chromium, "click and fit", range(len(app.frames)), frames)
    with serve_app(t2r, model, split="test", warm_up=True, scene_labels=vod) as app:
        second, _ = drive(app, chromium, "sentence first", indices, frames)
    return first + second


def table(runs: list[PairRun]) -> str:
    rows = [
        "| flow | pairs | clicks / pair | keys / pair (+ typing) | seconds / pair (median) "
        "| saved right | no click needed |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for flow in ("click and fit", "sentence first"):
        mine = [r for r in runs if r.flow == flow]
        if not mine:
            continue
        rows.append(
            f"| {flow} | {len(mine)} | {np.mean([r.clicks for r in mine]):.1f} | "
            f"{np.mean([r.keys for r in mine]):.1f} | {np.mean([r.seconds for r in mine]):.1f} "
            f"({np.median([r.seconds for r in mine]):.1f}) | "
            f"{sum(r.exact for r in mine)} / {len(mine)} | {sum(r.clicks == 0 for r in mine)} |"
        )
    return "\n".join(rows)


@pytest.mark.browser
@pytest.mark.slow
def test_sentence_first_takes_fewer_clicks_than_click_and_fit(tmp_path, chromium) -> None:
    runs = measure(2, 5, chromium, tmp_path)
    first = [r for r in runs if r.flow == "sentence first"]
    fit = [r for r in runs if r.flow == "click and fit"]
    assert first and len(first) == len(fit)
    assert all(r.exact for r in first)  # what is saved is the referents, after any correction
    assert sum(r.clicks for r in first) < sum(r.clicks for r in fit)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=6)
    parser.add_argument("--seed", type=int, default=5)
    args = parser.parse_args()
    chromium = find_chromium()
    if chromium is None:
        raise SystemExit("no Chromium found")
    with tempfile.TemporaryDirectory() as tmp:
        runs = measure(args.frames, args.seed, chromium, Path(tmp))
    for r in runs:
        print(r)
    print(table(runs))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
