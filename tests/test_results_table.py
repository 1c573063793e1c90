"""The RESULTS.md table maker: rows come from the JSON values, bad files are named."""

import json

import pytest

from model.results_table import (
    CLASSES,
    PROMPT_TYPES,
    ResultsTableError,
    by_depth_table,
    by_type_table,
    load_row,
    main,
    overall_table,
)


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
