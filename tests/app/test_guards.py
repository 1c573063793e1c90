"""The checks of forged browser messages (issue 21), without a browser: :mod:`app.guards`.
Through the websocket: tests/app/ws/test_reliability_ws.py."""

from __future__ import annotations

import logging
import math

import pytest
import viser
from viser import _messages as messages

from app.guards import (
    InputWarnings,
    check_camera,
    check_gui_update,
    check_numbers,
    shown,
)


@pytest.fixture(scope="module")
def gui():
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield server.gui
    server.stop()


def _value(handle, value):
    return check_gui_update(handle, {"value": value})


def test_numbers_are_finite_and_clamped_to_the_widget(gui) -> None:
    slider = gui.add_slider("Threshold", 0.0, 0.95, 0.01, 0.3)
    for forged in (math.nan, math.inf, -math.inf, "abc", None, True, [1.0], {"a": 1}):
        checked = _value(slider, forged)
        assert checked.value is None and checked.problem, forged
    assert _value(slider, 0.5).value == 0.5 and _value(slider, 0.5).problem is None
    assert _value(slider, 1e308).value == 0.95 and "clamped" in _value(slider, 1e308).problem
    assert _value(slider, -1).value == 0.0
    frame = gui.add_number("Frame #", 1, min=1, max=3, step=1)
    assert _value(frame, 2.6).value == 3 and isinstance(_value(frame, 2.6).value, int)
    assert _value(frame, 99).value == 3 and _value(frame, -5).value == 1
    unbounded = gui.add_number("Free", 0.0)
    assert _value(unbounded, 12.5).value == 12.5
    assert _value(unbounded, 1e308).value is None  # beyond any coordinate


def test_other_widgets_take_only_their_own_values(gui) -> None:
    box = gui.add_checkbox("Show", True)
    assert _value(box, False).value is False
    assert _value(box, [1, 2]).value is None and _value(box, 1).value is None
    dropdown = gui.add_dropdown("Split", ("train", "val"), initial_value="train")
    assert _value(dropdown, "val").value == "val" and _value(dropdown, "a" * 300).value is None
    group = gui.add_button_group("Frame", ("Previous", "Next"))
    assert _value(group, "Next").value == "Next" and _value(group, "Other").value is None
    button = gui.add_button("Run")
    assert _value(button, True).value is True and _value(button, "x").value is None
    text = gui.add_text("Prompt", "")
    assert _value(text, "the car").value == "the car"
    assert _value(text, 5).value is None and _value(text, "x" * 20_000).value is None
    for updates in ({"max": 1e308}, {"value": 1, "disabled": False}, [], "value"):
        assert check_gui_update(text, updates).value is None, updates


def test_scene_messages_with_bad_numbers_are_refused() -> None:
    good = messages.ScenePointerMessage(
        "click", (0.0, 0.0, 10.0), (0.5, 0.1, -1.0), ((0.5, 0.5),), None
    )
    assert check_numbers(good) is None
    for ray in ((math.nan, 0.0, 0.0), (1e308, 0.0, 0.0), (0.0, -math.inf, 0.0)):
        bad = messages.ScenePointerMessage("click", ray, (0.5, 0.1, -1.0), ((0.5, 0.5),), None)
        assert "ray_origin" in check_numbers(bad)
    drag = messages.TransformControlsUpdateMessage("/g", (1.0, 0.0, 0.0, 0.0), (1e9, 0.0, 0.0), "")
    assert "position" in check_numbers(drag)


def _camera(**changes) -> messages.ViewerCameraMessage:
    fields = {
        "wxyz": (1.0, 0.0, 0.0, 0.0),
        "position": (-10.0, 0.0, 5.0),
        "fov": 1.0,
        "near": 0.01,
        "far": 1000.0,
        "image_height": 600,
        "image_width": 800,
        "look_at": (10.0, 0.0, 0.0),
        "up_direction": (0.0, 0.0, 1.0),
    }
    return messages.ViewerCameraMessage(**{**fields, **changes})


def test_degenerate_cameras_are_refused() -> None:
    assert check_camera(_camera()) is None
    for changes in (
        {"look_at": (-10.0, 0.0, 5.0)},  # on the position: viser could not make a pose
        {"up_direction": (0.0, 0.0, 0.0)},
        {"wxyz": (0.0, 0.0, 0.0, 0.0)},
        {"fov": 0.0},
        {"fov": 4.0},
        {"near": 0.0},
        {"far": 0.001},
        {"image_height": 0},
        {"position": "abc"},
    ):
        assert check_camera(_camera(**changes)) is not None, changes


def test_warnings_are_one_line_per_connection_per_interval(caplog) -> None:
    caplog.set_level(logging.WARNING, logger="app.guards")
    now = [0.0]
    warnings = InputWarnings(interval=10.0, clock=lambda: now[0])
    assert warnings.warn("client 1", "refused a")
    assert not any(warnings.warn("client 1", f"refused {i}") for i in range(1999))
    assert warnings.warn("client 2", "refused b")  # another connection has its own line
    now[0] = 10.5
    assert warnings.warn("client 1", "refused c")
    lines = [r.getMessage() for r in caplog.records]
    assert lines == [
        "client 1: refused a",
        "client 2: refused b",
        "client 1: refused c (1999 more refused since the last line)",
    ]
    warnings.forget("client 1")
    assert warnings.warn("client 1", "again")  # a new connection with the same number


def test_shown_cuts_huge_values() -> None:
    assert shown("x" * 1_000_000).endswith("...") and len(shown("x" * 1_000_000)) == 60
    assert shown(1.5) == "1.5"
