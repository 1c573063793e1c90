"""The RESULTS.md table maker: rows come from the JSON values, bad files are named."""

import json

import pytest

from model.evaluation.grounding import SPLIT_NAMES
from model.evaluation.results_table import (
    PROMPT_TYPES,
    ResultsTableError,
    by_depth_table,
    by_type_table,
    grounding_splits_table,
    grounding_table,
    load_row,
    main,
    overall_table,
)
from scenes.geometry.classes import VOD

CLASSES = VOD.names


def _scores(base: float) -> dict[str, float]:
    out = {}
    for i, c in enumerate(CLASSES):
        out[f"{c}_3d_all"] = base + i
    out.update(mAP_3d=base + 1, mAOS=base / 2, mAP_3d_R40=base - 1)
    return out


def _result(base: float) -> dict:
    types = {
        t: {"frames": 3, "entire_area": _scores(base + 10 * k)} for k, t in enumerate(PROMPT_TYPES)
    }
    depth = {
        "0-10": {"gt_objects": 4, "entire_area": _scores(base + 5)},
        "50-60": {"gt_objects": 0, "entire_area": _scores(0.0)},
    }
    return {
        "by_depth": depth,
        "num_frames": 7,
        "entire_area": _scores(base),
        "roi": _scores(base + 20),
        "by_prompt_type": types,
    }


def test_rows_carry_the_json_values(tmp_path):
    path = tmp_path / "a.json"
    path.write_text(json.dumps(_result(40.0)))
    row = load_row(f"fusion={path}")
    table = overall_table([row]).splitlines()
    assert len(table) == 3
    cells = [c.strip() for c in table[2].strip("|").split("|")]
    ea = ["40.00", "41.00", "42.00", "**41.00**", "20.00", "39.00"]
    roi = ["60.00", "61.00", "62.00", "61.00", "30.00"]
    assert cells == ["fusion", "7", *ea, *roi]
    by_type = [c.strip() for c in by_type_table([row]).splitlines()[2].strip("|").split("|")]
    assert by_type == ["fusion", "41.00", "51.00", "61.00", "71.00"]
    depth = by_depth_table([row]).splitlines()
    assert depth[0] == "| model | 0-10 m | 50-60 m |"
    assert [c.strip() for c in depth[2].strip("|").split("|")] == ["fusion", "46.00", "-"]


def test_bad_files_are_named(tmp_path, capsys):
    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    with pytest.raises(ResultsTableError, match=r"broken.json.*line 1"):
        load_row(f"x={broken}")
    partial = tmp_path / "partial.json"
    result = _result(1.0)
    del result["roi"]["mAOS"]
    partial.write_text(json.dumps(result))
    with pytest.raises(ResultsTableError, match=r"partial.json \[roi\].*'mAOS'"):
        overall_table([load_row(f"x={partial}")])
    assert main([f"x={tmp_path / 'missing.json'}"]) == 2
    assert "missing.json" in capsys.readouterr().err
    with pytest.raises(ResultsTableError, match="NAME=PATH"):
        load_row("no-equals-sign")


def _summary(base: float) -> dict:
    keys = ("acc_25", "acc_50", "precision", "recall", "f1", "set_f1", "exact")
    return {"prompts": 5, **{k: base + i for i, k in enumerate(keys)}}


def _grounding(base: float) -> dict:
    return {
        "operating_threshold": 0.3,
        "overall": _summary(base),
        "by_prompt_type": {"depth": _summary(base + 1)},
        "by_group": {"attribute": _summary(base + 2), "single": _summary(base + 3)},
    }


def test_grounding_tables(tmp_path):
    result = _result(40.0)
    result["grounding"] = _grounding(10.0)
    result["baselines"] = {
        "oracle": {"entire_area": _scores(30.0), "grounding": _grounding(70.0)},
        "class_noun": {"entire_area": _scores(20.0), "grounding": _grounding(5.0)},
    }
    path = tmp_path / "g.json"
    path.write_text(json.dumps(result))
    row = load_row(f"new={path}")
    lines = grounding_table([row]).splitlines()
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in lines[2:]]
    assert [c[0] for c in cells] == ["new", "new class noun", "new oracle"]  # table order
    assert cells[0][1:] == [
        "5", "10.0", "11.0", "12.0", "13.0", "14.0", "**15.0**", "16.0", "41.00", "0.3"
    ]  # fmt: skip
    assert cells[2][2] == "70.0" and cells[2][-2] == "31.00"
    splits = grounding_splits_table([row]).splitlines()
    head = [c.strip() for c in splits[0].strip("|").split("|")]
    assert head[1:] == list(SPLIT_NAMES)
    first = [c.strip() for c in splits[2].strip("|").split("|")]
    by_name = dict(zip(head, first, strict=True))
    assert by_name["attribute"] == "12.0 / 17.0 / 18.0" and by_name["depth"] == "11.0 / 16.0 / 17.0"
    assert by_name["class_only"] == "-" and by_name["multiple"] == "-"
    # The older tables still read the new file.
    assert "**41.00**" in overall_table([row])


def test_grounding_tables_name_old_files(tmp_path, capsys):
    old = tmp_path / "old.json"
    old.write_text(json.dumps(_result(40.0)))
    with pytest.raises(ResultsTableError, match=r"old.json: missing field 'grounding'"):
        grounding_table([load_row(f"old={old}")])
    assert main([f"old={old}", "--grounding-splits"]) == 2
    assert "old.json" in capsys.readouterr().err
    assert main([f"old={old}"]) == 0
    broken = _result(40.0)
    broken["grounding"] = _grounding(1.0)
    del broken["grounding"]["overall"]["set_f1"]
    path = tmp_path / "broken.json"
    path.write_text(json.dumps(broken))
    with pytest.raises(ResultsTableError, match=r"broken.json \[b\] grounding.overall.*'set_f1'"):
        grounding_table([load_row(f"b={path}")])
