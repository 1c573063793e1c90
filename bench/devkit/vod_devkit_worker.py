"""The View-of-Delft devkit's side of ``bench/devkit/compare_vod_devkit.py``: run by it under the scratch
interpreter that has the devkit (``python bench/devkit/vod_devkit_worker.py FOLDER [FOLDER ...]``); it
imports the devkit, numpy and nothing of this project's.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np


def devkit_scores(folders: list[str]) -> None:
    """Print, as one JSON line, the devkit's numbers for each folder's ``labels`` scored against
    its ``devkit_preds`` and its ``raw_preds`` (keys ``FOLDER|KIND``; per area, the devkit's R11
    numbers and the R40 ones of ``do_eval``)."""
    import contextlib
    import io

    from vod.evaluation import Evaluation
    from vod.evaluation import evaluation_common as common
    from vod.evaluation.kitti_official_evaluate import do_eval

    names = ("Car", "Pedestrian", "Cyclist")
    first = np.full((3, 3), 0.7)
    first[:, 1:] = 0.5
    second = np.array([[0.7, 0.5, 0.5], [0.5, 0.25, 0.25], [0.5, 0.25, 0.25]])
    min_overlaps = np.stack([first, second])  # [table, metric (2d, bev, 3d), class]
    out = {}
    for folder in [f"{f}|{kind}" for f in folders for kind in ("devkit_preds", "raw_preds")]:
        root, kind = folder.split("|")
        labels, preds = str(Path(root) / "labels"), str(Path(root) / kind)
        res: dict[str, dict[str, float]] = {}
        with contextlib.redirect_stdout(io.StringIO()):
            official = Evaluation(test_annotation_file=labels).evaluate(
                result_path=preds, current_class=[0, 1, 2]
            )
            ids = sorted(p.stem for p in Path(preds).glob("*.txt"))
            gt = common.get_label_annotations(labels, ids)
            dt = common.get_label_annotations(preds, ids)
            for area, method in (("entire_area", 0), ("roi", 3)):
                (_, bev, d3, aos, _, bev40, d340, aos40) = do_eval(
                    gt, dt, [0, 1, 2], min_overlaps, True, custom_method=method
                )
                block = {k: float(v) for k, v in official[area].items()}
                for j, name in enumerate(names):
                    block[f"{name}_3d_all_R40"] = float(d340[j, 0, 1])
                    block[f"{name}_bev_all_R40"] = float(bev40[j, 0, 1])
                    block[f"{name}_aos_all_R40"] = float(aos40[j, 0, 1])
                    # do_eval's R11 must be the official numbers (a self-check of this worker)
                    assert abs(block[f"{name}_3d_all"] - d3[j, 0, 1]) < 1e-9
                    assert abs(block[f"{name}_bev_all"] - bev[j, 0, 1]) < 1e-9
                    assert abs(block[f"{name}_aos_all"] - aos[j, 0, 1]) < 1e-9
                res[area] = block
        out[folder] = res
    print(json.dumps(out))


if __name__ == "__main__":
    devkit_scores(sys.argv[1:])
