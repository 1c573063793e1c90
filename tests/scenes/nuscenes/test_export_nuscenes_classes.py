"""Issue 48 item 3: ``scenes.export_nuscenes`` writes every class it is given. A ``--classes
nuscenes`` synthetic source (3 worlds holding all ten classes, no camera; about 3 s) exported and
read back with the project's reader (NuScenesRoot): every actor an annotation of its class's
category, with nuScenes' attribute for it (moving or still), and commands about classes beyond
the three that read back into the nuScenes class set."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest

from scenes.geometry.classes import NUSCENES
from scenes.nuscenes.root import NuScenesRoot
from scenes.nuscenes.talk2car import read_commands

ATTRIBUTE_OF = {
    "vehicle": ("vehicle.moving", "vehicle.parked"),
    "human": ("pedestrian.moving", "pedestrian.standing"),
    "cycle": ("cycle.with_rider", "cycle.without_rider"),
}


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    from scenes.export_nuscenes import export
    from scenes.synth.generate import SynthSettings, generate_root

    base = tmp_path_factory.mktemp("nusc-classes")
    settings = SynthSettings(seed=2, classes="nuscenes", camera=None, prompts_per_world=8)
    generate_root(base / "synth", 24, settings, split_fractions=(0.5, 0.25, 0.25))
    export(base / "synth", base / "nusc", seed=1)
    return base / "synth", base / "nusc"


def _source_actors(synth: Path) -> Counter[tuple[str, bool]]:
    """(class, moving) of every actor of the source's frames (each world's frame once)."""
    from scenes.talk2radar.root import Talk2RadarRoot

    root = Talk2RadarRoot(synth)
    seen: dict[tuple, tuple[str, bool]] = {}
    for split in ("train", "val", "test"):
        for sid in root.ids(split):
            meta = root.source_meta(sid)
            for a in meta.actors:
                seen[(root.frame_key(sid), a.actor_id)] = (a.cls, a.is_moving)
    return Counter(seen.values())


def test_every_class_is_written_with_its_category_and_attribute(exported) -> None:
    synth, nusc = exported
    root = NuScenesRoot(nusc)
    found: Counter[tuple[str, bool]] = Counter()
    for sample in root.samples:
        _, categories, attributes = root.annotation_boxes(sample)
        for category, attrs in zip(categories, attributes, strict=True):
            cls = NUSCENES.category_class(category, attrs)
            assert cls is not None, category
            assert category == NUSCENES.get(cls).categories[0]
            kind = "cycle" if cls in ("Bicycle", "Motorcycle") else category.split(".")[0]
            if kind == "movable_object":
                assert attrs == (), (category, attrs)
                found[(cls, False)] += 1
                continue
            assert len(attrs) == 1 and attrs[0] in ATTRIBUTE_OF[kind], (category, attrs)
            found[(cls, attrs[0] == ATTRIBUTE_OF[kind][0])] += 1
    source = _source_actors(synth)
    source = Counter(
        {(c, m and c not in ("TrafficCone", "Barrier")): n for (c, m), n in source.items()}
    )
    assert found == source
    assert {c for c, _ in found} == set(NUSCENES.names)  # all ten in this source


def test_commands_about_classes_beyond_the_three_read_back(exported) -> None:
    _, nusc = exported
    root = NuScenesRoot(nusc)
    classes: Counter[str] = Counter()
    for split in ("train", "val", "test"):
        found = read_commands(nusc / "commands", split, root, NUSCENES)
        assert not found.skipped
        classes.update(found.referent[c.command_token].cls for c in found.commands)
    assert len(set(classes) - {"Car", "Pedestrian", "Bicycle"}) >= 2, classes
