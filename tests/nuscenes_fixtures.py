"""Small nuScenes roots for tests, written by ``scenes.export_nuscenes`` (the project's export).

:func:`write_nuscenes_root` generates a tiny synthetic root (no camera) and exports it;
:func:`add_out_of_class` then puts one annotation outside the class set (a parked
``vehicle.truck``, 8 m beside the sample's first annotation) into every sample, as nuScenes has
trucks and barriers around every car, so that the training side's "ignored, neither target nor
negative" path runs on a real root; :func:`prefix_descriptions` makes some scenes rain and night
ones (the table's subsets). tests/conftest.py's ``nuscenes_training_root`` fixture is the one
session-wide copy.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

TRUCK = "vehicle.truck"
"""The out-of-class category :func:`add_out_of_class` adds."""
TRUCK_OFFSET = np.array([0.0, 8.0, 0.0])
"""Where the truck goes: this far (metres, global frame) from the sample's first annotation."""


def write_nuscenes_root(
    path: Path, seed: int = 7, worlds: int = 4, prompts_per_world: int = 6
) -> Path:
    """A synthetic root of ``worlds`` worlds (half train, half val) exported as nuScenes with
    Talk2Car commands at ``path`` (``path/commands/{train,val}_commands.json``); returns ``path``.
    The synthetic source is written beside it (``path`` + ``-synth``)."""
    from scenes.export_nuscenes import export
    from scenes.synth.generate import SynthSettings, generate_root

    source = path.parent / f"{path.name}-synth"
    settings = SynthSettings(seed=seed, prompts_per_world=prompts_per_world, camera=None)
    generate_root(source, worlds * prompts_per_world, settings, split_fractions=(0.5, 0.5, 0.0))
    export(source, path, splits=("train", "val"), seed=seed)
    return path


def prefix_descriptions(path: Path, prefixes: tuple[str, ...] = ("Rain, ", "Night, ")) -> None:
    """Prefix the scene descriptions of the nuScenes root at ``path`` with ``prefixes`` in turn,
    as nuScenes writes rain and night scenes ("Night, big street, bus stop, ...")."""
    folder = next(p for p in path.iterdir() if p.is_dir() and p.name.startswith("v1.0-"))
    scenes = json.loads((folder / "scene.json").read_text())
    for i, scene in enumerate(scenes):
        scene["description"] = prefixes[i % len(prefixes)] + scene["description"]
    (folder / "scene.json").write_text(json.dumps(scenes, indent=1) + "\n")


def add_out_of_class(path: Path, category: str = TRUCK) -> int:
    """Add a parked ``category`` annotation (8 m from the first annotation, global frame) with
    its own instance to every sample of the nuScenes root at ``path``; returns how many."""
    folder = next(p for p in path.iterdir() if p.is_dir() and p.name.startswith("v1.0-"))
    tables = {
        name: json.loads((folder / f"{name}.json").read_text())
        for name in ("category", "attribute", "instance", "sample_annotation")
    }
    category_token = next(c["token"] for c in tables["category"] if c["name"] == category)
    parked = next(a["token"] for a in tables["attribute"] if a["name"] == "vehicle.parked")
    first: dict[str, dict] = {}
    for ann in tables["sample_annotation"]:
        first.setdefault(ann["sample_token"], ann)
    for i, (_, ann) in enumerate(sorted(first.items())):
        token = f"{category.replace('.', '-')}-{i:04d}"
        tables["instance"].append(
            {
                "token": f"instance-{token}",
                "category_token": category_token,
                "nbr_annotations": 1,
                "first_annotation_token": f"annotation-{token}",
                "last_annotation_token": f"annotation-{token}",
            }
        )
        tables["sample_annotation"].append(
            {
                **ann,
                "token": f"annotation-{token}",
                "instance_token": f"instance-{token}",
                "translation": list(np.asarray(ann["translation"]) + TRUCK_OFFSET),
                "size": [2.5, 8.0, 3.0],
                "attribute_tokens": [parked],
                "prev": "",
                "next": "",
            }
        )
    for name in ("instance", "sample_annotation"):
        (folder / f"{name}.json").write_text(json.dumps(tables[name], indent=1) + "\n")
    return len(first)


__all__ = ["TRUCK", "add_out_of_class", "prefix_descriptions", "write_nuscenes_root"]
