"""How close *Fit to points* lands to the true box after a ground click:
``python -m bench.studies.fit_accuracy [--data data/default] [--samples 120]``.

For every distinct actor 3-35 m ahead (``|y| < 15`` m) in the first ``--samples`` samples of a
synthetic root (its ``meta/`` sidecars hold the true boxes), a box is placed as a ground click
places it (:func:`annotate.draft.default_box` of the actor's class at its centre, on its ground)
and fitted to the frame's LiDAR points with :func:`annotate.fitting.fit_box` three ways: without
the class (no size prior), with the class completed to the plausible minimum, and with the class
completed to the typical size (the default). Prints, per class and way: the median BEV centre
error, the share of fits more than 0.5 m off, the median length and width errors, and the share
with a heading more than 30 degrees off (heading modulo 180 degrees: points cannot tell front from
back). Objects with too few points for a fit are counted apart.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes.utils.cli import command_parser, option, run_command

_REPO = Path(__file__).resolve().parents[2]
if str(_REPO) not in sys.path:
    sys.path.insert(0, str(_REPO))

from annotate.draft import default_box  # noqa: E402
from annotate.fitting import BoxRegion, FitConfig, FitError, fit_box  # noqa: E402
from scenes.geometry.boxes import wrap_yaw  # noqa: E402
from scenes.talk2radar.root import Talk2RadarRoot  # noqa: E402

WAYS: tuple[tuple[str, bool, FitConfig], ...] = (
    ("no class", False, FitConfig()),
    ("class, minimum", True, FitConfig(grow_to_typical=False)),
    ("class, typical (default)", True, FitConfig()),
)


def cases(root: Talk2RadarRoot, samples: int) -> list[tuple[np.ndarray, str, np.ndarray]]:
    """``(lidar (N, 4), class, true box (7,))`` of each distinct actor 3-35 m ahead."""
    ids = sorted({sid for split in root.splits() for sid in root.ids(split)})[:samples]
    seen: set[tuple[float, ...]] = set()
    out = []
    for sid in ids:
        sample = root.load(sid)
        for actor in sample.meta.actors if sample.meta is not None else ():
            key = tuple(np.round(actor.box, 2))
            if key in seen or not (3.0 < actor.box[0] < 35.0 and abs(actor.box[1]) < 15.0):
                continue
            seen.add(key)
            out.append((sample.lidar, actor.cls, actor.box))
    return out


def errors(lidar: np.ndarray, cls: str, truth: np.ndarray, use_cls: bool, cfg: FitConfig):
    """``(centre, length, width, heading deg)`` errors of one fit, or None without enough points."""
    ground = float(truth[2] - truth[5] / 2.0)
    rough = default_box(cls, float(truth[0]), float(truth[1]), ground_z=ground)
    try:
        box = fit_box(lidar, BoxRegion(rough), cls=cls if use_cls else None, config=cfg).box
    except FitError:
        return None
    heading = np.degrees(abs(wrap_yaw(2.0 * (box[6] - truth[6]))) / 2.0)
    return (
        float(np.hypot(box[0] - truth[0], box[1] - truth[1])),
        abs(box[3] - truth[3]),
        abs(box[4] - truth[4]),
        heading,
    )


@dataclass(frozen=True, kw_only=True)
class FitAccuracyOptions:
    """The flags of ``python -m bench.studies.fit_accuracy``."""

    data: Path = option(_REPO / "data" / "default")
    samples: int = option(120)


def build_parser() -> argparse.ArgumentParser:
    """``python -m bench.studies.fit_accuracy``'s parser."""
    return command_parser(
        "python -m bench.studies.fit_accuracy", __doc__.splitlines()[0], FitAccuracyOptions
    )


def _run(args: FitAccuracyOptions) -> int:
    """The command run as ``args`` says."""
    objects = cases(Talk2RadarRoot(args.data), args.samples)
    print(f"{len(objects)} objects of {args.data} (first {args.samples} samples), 3-35 m ahead")
    print(
        "| class | fit | n | centre median m | > 0.5 m off | length err m | width err m | heading > 30 deg |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for cls in ("Car", "Pedestrian", "Cyclist"):
        for name, use_cls, cfg in WAYS:
            rows = [errors(lid, c, box, use_cls, cfg) for lid, c, box in objects if c == cls]
            got = np.array([r for r in rows if r is not None]).reshape(-1, 4)
            if not len(got):
                continue
            print(
                f"| {cls} | {name} | {len(got)} (+{len(rows) - len(got)} too few points) | "
                f"{np.median(got[:, 0]):.2f} | {100 * np.mean(got[:, 0] > 0.5):.0f} % | "
                f"{np.median(got[:, 1]):.2f} | {np.median(got[:, 2]):.2f} | "
                f"{100 * np.mean(got[:, 3] > 30):.0f} % |"
            )
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    return run_command(build_parser(), FitAccuracyOptions, _run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
