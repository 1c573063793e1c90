"""The app serving a model of the ``nuscenes`` class set (issue 36), through its websocket as a
browser: the legend names and colours its ten classes, the Annotate tab's class controls offer
exactly that set (a new box of a class beyond the three, sized as its class), the heatmap and the
answers are its classes', and the empty answer is worded from its plurals (item 4).

The model is the small TPCNet with the Bi-GRU text encoder, untrained (quick to build)."""

from __future__ import annotations

import numpy as np
import pytest

from annotate import default_box
from app.annotate_tab import AnnotationPanel
from app.annotate_tab.keys import Key, check_hotkeys, keys_of
from app.annotate_tab.widgets import CHANGE_CLASS, NEW_BOX_CLASS, class_key
from app.text import md_text
from app.view.scene_view import CLASS_LEGEND
from scenes.geometry.classes import NUSCENES, VOD
from scenes.talk2radar.root import Talk2RadarRoot


@pytest.fixture(scope="module")
def nuscenes_app(
    tmp_path_factory, write_tiny_root, torch_threads, serve_app, untrained_nuscenes_app_model
):
    root = write_tiny_root(tmp_path_factory.mktemp("classes") / "root")
    with torch_threads(1):
        model = untrained_nuscenes_app_model()
        with serve_app(root, model) as app:
            yield app


def test_a_nuscenes_model_is_drawn_named_and_annotated_in_its_classes(
    nuscenes_app, ws_client
) -> None:
    app = nuscenes_app
    before = set(app.sessions)
    client = ws_client(app.port)
    try:
        client.pump_until(
            lambda: (
                "/scene/lidar" in client.nodes and "Save pair" in client.gui and "Run" in client.gui
            ),
            30,
            "the scene, the Query and the Annotate tabs",
        )
        session = app.sessions[(set(app.sessions) - before).pop()]
        # the legend names the model's ten classes
        assert f"{CLASS_LEGEND}: {', '.join(NUSCENES.names)}" in client.gui
        assert f"{CLASS_LEGEND}: {', '.join(VOD.names)}" not in client.gui
        # the Annotate tab offers exactly the served checkpoint's class set
        assert client.dropdown(NEW_BOX_CLASS) == NUSCENES.names
        panel: AnnotationPanel = next(p for p in app.annotations.panels() if p.session is session)
        assert panel.w.relabel.options == NUSCENES.names
        assert panel.w.relabel.label == CHANGE_CLASS
        client.pump_until(lambda: panel.frame is not None, 10, "the draft's frame")
        client.set(NEW_BOX_CLASS, "Truck")
        client.pump_until(lambda: panel.w.cls.value == "Truck", 5, "the class")
        ground = panel.frame.ground_z
        client.click_ground(14.0, 4.0, ground)
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 5, "the truck")
        truck = panel.draft.boxes[0]
        assert truck.cls == "Truck"
        np.testing.assert_allclose(truck.box, default_box("Truck", 14.0, 4.0, ground), atol=1e-9)
        assert truck.box[3:6] == pytest.approx(NUSCENES.get("Truck").mean_size)
        # a forged class outside the set is refused; C cycles within the set
        client.click(CHANGE_CLASS, "Cyclist")
        client.drain(0.3)
        assert panel.draft.boxes[0].cls == "Truck"
        client.click(CHANGE_CLASS, "TrafficCone")
        client.pump_until(lambda: panel.draft.boxes[0].cls == "TrafficCone", 5, "the relabel")
        # the pair is saved with the set's class name and read back into the set
        client.set("Pair prompt", "the traffic cone on the left")
        client.set("Split", "test")
        client.set("Annotator", "ada")
        client.pump_until(lambda: panel.w.annotator.value == "ada", 5, "the annotator")
        client.pump_until(lambda: bool(panel.draft.prompt), 5, "the prompt")
        client.click("Save pair")
        client.pump_until(
            lambda: any(t.startswith("Saved pair") for t, _ in client.notifications), 10, "saved"
        )
        sid = next(t for t, _ in client.notifications if t.startswith("Saved pair")).split()[-1]
        root = app.frames.root.path
        assert Talk2RadarRoot(root, classes=NUSCENES).load(sid).classes == ("TrafficCone",)
        assert Talk2RadarRoot(root).load(sid).classes == ()  # no vod class

        # answers: boxes of the model's classes, the heatmap coloured per its ten channels
        client.set("Score threshold", 0.0)
        client.set("Prompt", "the truck on the left")
        client.click("Run")
        client.pump_until(lambda: "/pred/edges" in client.nodes, 60, "the answer's boxes")
        answer = session.answer
        assert answer is not None and len(answer.predictions.classes)
        assert set(answer.predictions.classes) <= set(NUSCENES.names)
        assert answer.predictions.heatmaps.shape[0] == 10
        assert len(session.heatmap_view.colors) == 10
        # item 4: nothing boxed -> the honest empty answer, from the checkpoint's own class set
        client.set("Score threshold", 0.95)
        client.set("Prompt", "the tram\n")
        said = md_text(f"No object here matches; I find {NUSCENES.plural_list()}.")
        client.pump_until(
            lambda: any(t.startswith(said) for t in client.markdown.values()), 60, "the words"
        )
    finally:
        client.close()


def test_a_ten_class_set_gets_keys_1_to_9_and_no_key_runs_two_actions() -> None:
    """Key 0 is *Refers to nothing*; with ten classes it also chose the tenth (viser runs every
    command of a hotkey), so class keys go 1 to 9 and :func:`keys_of` refuses a shared key."""
    for classes in (VOD, NUSCENES):
        actions: dict[tuple[str, str | None], set[str]] = {}
        for k in keys_of(classes.names):
            if k.key is not None:
                actions.setdefault((k.key.lower(), k.modifier), set()).add(k.action)
        assert all(len(a) == 1 for a in actions.values()), actions
    shown = [k.shown for k in keys_of(NUSCENES.names) if k.action.startswith("new_class_")]
    assert shown == [str(i) for i in range(1, 10)]
    assert class_key(8) == "9" and class_key(9) is None
    with pytest.raises(ValueError, match="key 0 would run both"):
        check_hotkeys([*keys_of(), Key("new_class_9", "0", None, "", "0", "Placing")])
