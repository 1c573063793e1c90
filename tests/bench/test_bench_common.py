"""Unit tests of the benchmark helpers (bench/common.py, bench/run_all.py rendering).

The benchmarks themselves are scripts, not tests; these check the statistics, the Markdown and
JSON output, the memory and FLOP counters and the document rendering on hand-made inputs.
"""

from __future__ import annotations

import json
import math
import os
import time

import pytest
import torch

from bench.common import (
    BenchResult,
    BenchResultError,
    LiveTensorMemory,
    Machine,
    Table,
    Target,
    count_flops,
    count_params,
    fmt_bytes,
    fmt_count,
    fmt_flops,
    fmt_ms,
    fmt_ratio,
    interleaved_ms,
    machine_info,
    peak_memory_bytes,
    percentile,
    read_result,
    summarize,
    write_result,
)
from bench.run_all import render


def _machine(command: str = "python -m bench.example --quick") -> Machine:
    return Machine(
        cpu_model="Test CPU 9000",
        cores=2,
        memory_gib=24.0,
        torch_version="2.x",
        torch_threads=2,
        python="3.11.7",
        platform="Linux-test",
        gpu=None,
        load_average=(1.5, 1.25, 1.0),
        date="2026-01-02T03:04:05+00:00",
        command=command,
    )


def _result(targets: list[Target] | None = None) -> BenchResult:
    table = Table(
        title="Example",
        columns=("method", "ms"),
        rows=(("a", "1.00"), ("b|c", "2.00")),
        notes=("a note",),
    )
    data = {"values": [1, 2, 3]}
    if targets is not None:
        data["targets"] = [t.__dict__ for t in targets]
    return BenchResult(
        name="latency",
        title="Example benchmark",
        machine=_machine(),
        tables=(table,),
        findings=("finding one",),
        data=data,
        seconds=12.3,
    )


# --------------------------------------------------------------------------- statistics


def test_percentile_interpolates_between_order_statistics() -> None:
    values = [4.0, 1.0, 3.0, 2.0]
    assert percentile(values, 50) == pytest.approx(2.5)
    # position 0.9 * 3 = 2.7 -> 3 + 0.7 * (4 - 3)
    assert percentile(values, 90) == pytest.approx(3.7)
    assert percentile(values, 0) == 1.0
    assert percentile(values, 100) == 4.0
    assert percentile([7.0], 90) == 7.0


def test_percentile_rejects_bad_input() -> None:
    with pytest.raises(ValueError):
        percentile([], 50)
    with pytest.raises(ValueError):
        percentile([1.0], 101)


def test_summarize() -> None:
    s = summarize([3.0, 1.0, 2.0])
    assert (s.n, s.median, s.mean, s.min, s.max) == (3, 2.0, 2.0, 1.0, 3.0)
    assert s.p90 == pytest.approx(2.8)  # position 1.8 -> 2 + 0.8
    with pytest.raises(ValueError):
        summarize([])


def test_interleaved_ms_rotates_the_order_and_respects_the_budget() -> None:
    order: list[str] = []

    def make(name: str, sleep: float = 0.0):
        def call() -> None:
            order.append(name)
            if sleep:
                time.sleep(sleep)

        return call

    samples = interleaved_ms({"a": make("a"), "b": make("b"), "c": make("c")}, 2, 10.0)
    assert order == ["a", "b", "c", "b", "c", "a"]
    assert [len(v) for v in samples.values()] == [2, 2, 2]
    order.clear()
    samples = interleaved_ms({"slow": make("slow", 0.02), "fast": make("fast")}, 3, 0.01)
    assert len(samples["slow"]) == 1  # over budget after its first call
    assert len(samples["fast"]) == 3
    assert samples["slow"][0] >= 20.0


# --------------------------------------------------------------------------- output


def test_table_markdown() -> None:
    table = Table(
        title="T",
        columns=("name", "value"),
        rows=(("x|y", "1"),),
        notes=("n1",),
    )
    assert table.to_markdown() == (
        "### T\n\n| name | value |\n| --- | ---: |\n| x\\|y | 1 |\n\n- n1"
    )
    untitled = Table(title="", columns=("a",), rows=(("1",),), align=("r",))
    assert untitled.to_markdown() == "| a |\n| ---: |\n| 1 |"


def test_table_rejects_ragged_rows() -> None:
    with pytest.raises(ValueError, match="row 0 has 1 cells for 2 columns"):
        Table(title="bad", columns=("a", "b"), rows=(("1",),))
    with pytest.raises(ValueError, match="align"):
        Table(title="bad", columns=("a",), rows=(), align=("c",))


def test_result_markdown_has_machine_command_tables_and_findings() -> None:
    text = _result().to_markdown()
    assert text.startswith("## Example benchmark\n")
    assert "Test CPU 9000, 2 cores, 24.0 GiB RAM, no GPU; torch 2.x (2 threads)" in text
    assert "load average 1.50 / 1.25 / 1.00" in text
    assert "*Command:* `python -m bench.example --quick` (ran 12 s)." in text
    assert "| b\\|c | 2.00 |" in text
    assert "- finding one" in text


def test_result_json_round_trip(tmp_path) -> None:
    result = _result([Target("x", 1.0, 2.0, "ms", False)])
    path = write_result(result, tmp_path)
    assert path == tmp_path / "latency.json"
    again = read_result(path)
    assert again == result


def test_read_result_names_the_file_and_the_field(tmp_path) -> None:
    data = _result().to_json()
    del data["machine"]["command"]
    path = tmp_path / "latency.json"
    path.write_text(json.dumps(data))
    with pytest.raises(BenchResultError, match=r"latency\.json: machine: missing field 'command'"):
        read_result(path)
    path.write_text("{\n  oops")
    with pytest.raises(BenchResultError, match=r"latency\.json: not valid JSON \(line 2"):
        read_result(path)


def test_machine_info_records_the_command() -> None:
    m = machine_info("python -m bench.perf.latency")
    assert m.command == "python -m bench.perf.latency"
    affinity = getattr(os, "sched_getaffinity", None)
    assert m.cores == (len(affinity(0)) if affinity else os.cpu_count())
    assert m.torch_threads == torch.get_num_threads()
    assert m.torch_version == torch.__version__
    assert m.cpu_model in m.describe()


def test_formatters() -> None:
    assert fmt_ms(1234.4) == "1,234"
    assert fmt_ms(12.34) == "12.3"
    assert fmt_ms(1.234) == "1.23"
    assert fmt_ratio(57.49) == "57.5x"
    assert fmt_ratio(math.nan) == "n/a"
    assert fmt_count(648_347) == "648 k"
    assert fmt_count(999) == "999"
    assert fmt_count(22_700_000) == "22.7 M"
    assert fmt_flops(5_872_025_600) == "5.87 GFLOP"
    assert fmt_bytes(1536) == "1.5 KiB"
    assert fmt_bytes(3 * 1024**3) == "3 GiB"


def test_target_verdicts() -> None:
    assert Target("t", 40.0, 50.0, "ms", False).met
    assert not Target("t", 60.0, 50.0, "ms", False).met
    assert Target("r", 57.5, 50.0, "x", True).met
    assert not Target("r", math.nan, 50.0, "x", True).met
    assert Target("t", 60.0, 50.0, "ms", False).describe() == (
        "t: 60.0 ms (target <= 50.0 ms): **MISSED**"
    )


# --------------------------------------------------------------------------- counters


def test_live_tensor_memory_peak_is_hand_computable() -> None:
    x = torch.randn(1000, 1000)  # allocated before: never counted

    def fn() -> torch.Tensor:
        a = x @ x  # 4 MB
        b = a * 2  # 4 MB: 8 MB live
        del a  # 4 MB
        c = b.softmax(-1)  # 8 MB live again
        c.view(-1)  # a view of c: no new memory
        x.view(-1)  # a view of an input: not counted
        return c.sum()  # 4 bytes

    with LiveTensorMemory() as mem:
        out = fn()
    assert mem.peak == 8_000_004
    assert mem.live == 4  # only the returned scalar is still alive
    del out
    assert mem.live == 0


def test_peak_memory_bytes_on_cpu_ignores_inputs_and_weights() -> None:
    layer = torch.nn.Linear(64, 32)
    x = torch.randn(10, 64)

    def fn() -> None:
        with torch.no_grad():
            layer(x)

    assert peak_memory_bytes(fn) == 10 * 32 * 4


def test_count_flops_and_params() -> None:
    layer = torch.nn.Linear(64, 32)
    x = torch.randn(10, 64)
    flops = count_flops(lambda: layer(x))
    assert flops.total == 2 * 10 * 64 * 32
    conv = torch.nn.Conv2d(3, 8, 3, padding=1, bias=False).to("meta")
    y = torch.empty(1, 3, 5, 5, device="meta")
    assert count_flops(lambda: conv(y)).total == 2 * 8 * 5 * 5 * 3 * 9
    assert count_params(layer) == 64 * 32 + 32
    layer.bias.requires_grad_(False)
    assert count_params(layer, trainable_only=True) == 64 * 32


# --------------------------------------------------------------------------- document


def test_render_summarises_targets_and_keeps_each_section_header(tmp_path) -> None:
    result = _result(
        [
            Target("`ground` median, small, CPU", 80.0, 50.0, "ms", False),
            Target("ratio", 60.0, 50.0, "x", True),
        ]
    )
    text = render(
        {"latency": result}, {}, tmp_path / "synth.json", "python -m bench.run_all", 600.0
    )
    assert text.startswith("# Performance\n")
    assert "Generated by `python -m bench.run_all` in 10.0 min" in text
    assert "| `ground` median, small, CPU | 80.0 ms | <= 50 ms | **MISSED** |" in text
    assert "| ratio | 60.0 x | >= 50 x | met |" in text
    assert "### Notes on the misses" in text
    assert "## Example benchmark" in text
    assert "*Command:* `python -m bench.example --quick`" in text
    assert "HOOK" in text  # no synth.json: the scene generation section says so


def test_render_includes_scene_generation_results(tmp_path) -> None:
    synth = tmp_path / "synth.json"
    synth.write_text(
        json.dumps(
            {
                "command": "python bench/perf/bench_synth.py --worlds 2 --frames 4",
                "machine": {"load_average_before": 2.5},
                "markdown": "| stage | s |\n| --- | ---: |\n| world | 0.1 |",
            }
        )
    )
    text = render({}, {}, synth, "python -m bench.run_all", None)
    assert "## Scene generation speed" in text
    assert "`python bench/perf/bench_synth.py --worlds 2 --frames 4`" in text
    assert "load average 2.50 at the start" in text
    assert "| world | 0.1 |" in text
    failed = render({}, {"latency": "exit code 1"}, synth, "python -m bench.run_all", 1.0)
    assert "- `latency`: exit code 1" in failed


# --------------------------------------------------------------------------- latency (both paths)


def _calls(walls: list[float], stages: dict[str, list[float]]):
    from bench.perf.latency_measure import Call

    return [
        Call(w, {k: v[i] for k, v in stages.items()}, boxes=3, answer=1)
        for i, w in enumerate(walls)
    ]


def _path_calls(cached: list[float], fresh: list[float], repeated: list[float], spec):
    from bench.perf.latency_measure import PathCalls

    ground = {k: [1.0] * len(cached) for k in spec.ground_stages}
    scene = {k: [2.0] * len(fresh) for k in spec.scene_stages + spec.ground_stages}
    return PathCalls(
        _calls(cached, ground),
        _calls(fresh, scene),
        _calls(repeated, {k: [0.5] * len(repeated) for k in spec.ground_stages}),
    )


def test_latency_targets_and_side_by_side_table() -> None:
    from bench.perf.latency_measure import REFERENT, TPCNET
    from bench.perf.latency_report import side_by_side_table, targets

    calls = {
        "referent": _path_calls([20.0, 24.0, 30.0], [140.0, 150.0, 170.0], [8.0], REFERENT),
        "tpcnet": _path_calls([60.0, 70.0, 80.0], [160.0, 170.0, 180.0], [40.0], TPCNET),
    }
    ref = targets(REFERENT, calls["referent"], "small, CPU")
    tpc = targets(TPCNET, calls["tpcnet"], "small, CPU")
    assert [(t.value, t.limit, t.met) for t in ref] == [(24.0, 25.0, True), (150.0, 150.0, True)]
    assert [(t.value, t.met) for t in tpc] == [(70.0, False), (170.0, False)]
    # The TPCNet path's names start like bench.run_all's notes on DGGF; the referent path's not.
    assert tpc[0].name.startswith("`ground` median") and ref[0].name.startswith("Referent path")
    table = side_by_side_table(
        "Both", [REFERENT, TPCNET], calls, {"referent": "untrained", "tpcnet": "`x.pt`"}
    )
    assert [r[0] for r in table.rows] == [
        "referent path (untrained)",
        "TPCNet path (DGGF) (`x.pt`)",
        "**Target** (issue 15)",
    ]
    assert table.rows[0][2:6] == ("24.0", "28.8", "150", "166")
    assert table.rows[-1][2] == "<= 25" and table.rows[-1][4] == "<= 150"
    assert table.rows[0][-1] == "3.0 / 1.0"


def test_latency_stage_check_and_detect_tables() -> None:
    from bench.perf.latency_measure import DETECT_NAMES, REFERENT
    from bench.perf.latency_report import calls_data, check_table, detect_table, stage_table

    calls = _calls([10.0, 12.0], {"text": [6.0, 7.0], "referent": [2.0, 3.0], "decode": [1.0, 1.0]})
    table = stage_table("t", calls, REFERENT.ground_stages, REFERENT.stage_names)
    rows = {r[0]: r for r in table.rows}
    assert rows["text encoder (MiniLM)"][1] == "6.50"
    assert rows["other (input checks, result packing)"][1] == "1.00"  # 10-9 and 12-11
    assert rows["**wall-clock total**"][1:3] == ("11.0", "11.8")
    outside = {"text": [6.0, 8.0], "referent": [2.5, 2.5], "decode": [1.0, 2.0]}
    check = check_table("c", calls, outside, REFERENT.stage_names, "by hand")
    assert check.rows[0] == ("text encoder (MiniLM)", "6.50", "7.00", "0.50")
    assert "first 2 prompts" in check.notes[0]
    parts = {
        "neck": [1.0, 1.0],
        "head": [2.0, 4.0],
        "decode": [10.0, 20.0],
        "candidates": [1.0, 1.0],
    }
    detect = detect_table("d", parts, [15.0, 27.0], DETECT_NAMES)
    assert detect.rows[-2][1:] == ("20.0", "24.8")  # the parts sum to 14 and 26 ms
    assert detect.rows[-1][1] == "21.0"
    path = _path_calls([10.0], [100.0], [5.0], REFERENT)
    data = calls_data(REFERENT, path)
    assert set(data["encode_stages_ms"]) == {*REFERENT.scene_stages, *REFERENT.ground_stages}
    assert data["answer_per_prompt"] == [1] and data["cached_ground_ms"] == [10.0]


def test_latency_model_choice_follows_the_checkpoints_grounding(tmp_path, monkeypatch) -> None:
    import bench.perf.latency_measure as lm
    from model import build_model
    from model.checkpoint import save_checkpoint

    torch.manual_seed(0)
    served, faithful = tmp_path / "tpcnet-small.pt", tmp_path / "tpcnet-small-faithful.pt"
    monkeypatch.setattr(lm, "REPO", tmp_path)
    monkeypatch.setattr(lm, "CHECKPOINT", served)
    monkeypatch.setattr(lm, "FAITHFUL_CHECKPOINT", faithful)
    missing = lm.load_path_model(lm.REFERENT, "small", "cpu")
    assert not missing.trained and "`tpcnet-small.pt` does not exist" in missing.note
    assert missing.model.cfg.grounding == "referent" and not missing.model.training
    save_checkpoint(served, build_model("small"), step=7)  # the faithful model, served for now
    old = lm.load_path_model(lm.REFERENT, "small", "cpu")
    assert not old.trained and "has grounding 'tpcnet'" in old.note and old.short == "untrained"
    tpc = lm.load_path_model(lm.TPCNET, "small", "cpu")  # falls back to the served one
    assert tpc.trained and tpc.short == "`tpcnet-small.pt`" and "(step 7)" in tpc.note
    save_checkpoint(served, build_model("small", grounding="referent"), step=9)
    new = lm.load_path_model(lm.REFERENT, "small", "cpu")
    assert new.trained and new.model.cfg.grounding == "referent" and "(step 9)" in new.note


def test_common_re_exports_the_split_modules() -> None:
    import bench.common as common
    import bench.measure as measure
    import bench.report as report
    import bench.workloads as workloads

    for module in (measure, report, workloads):
        public = [
            n
            for n, v in vars(module).items()
            if not n.startswith("_") and getattr(v, "__module__", "") == module.__name__
        ]
        assert public and all(getattr(common, n) is getattr(module, n) for n in public)
    assert set(common.__all__) <= set(vars(common))
