"""Report rendering of :mod:`bench.perf.latency`: Markdown tables from the measurements of
:mod:`bench.perf.latency_measure` (no timing happens here)."""

from __future__ import annotations

from collections.abc import Sequence

from bench.measure import summarize
from bench.perf.latency_measure import Call, PathCalls, PathSpec, ProfileRow
from bench.report import Table, Target, fmt_ms

GROUND_TARGET_MS = 25.0
"""Issue 15: ``ground`` on a cached scene, prompts new to the text cache, median."""
ENCODE_GROUND_TARGET_MS = 150.0
"""Issue 15: ``encode_scene`` + ``ground``, median."""

LATENCY_COLUMNS = ("path", "prompts", "median ms", "p90 ms", "mean ms", "max ms")


def walls(calls: Sequence[Call]) -> list[float]:
    """The wall-clock milliseconds of ``calls``."""
    return [c.wall_ms for c in calls]


def median(calls: Sequence[Call]) -> float:
    """Median wall-clock milliseconds of ``calls``."""
    return summarize(walls(calls)).median


def summary_row(label: str, samples: Sequence[float]) -> tuple[str, ...]:
    """``label``, count, median, p90, mean, max (the :data:`LATENCY_COLUMNS`)."""
    s = summarize(samples)
    return (label, str(s.n), fmt_ms(s.median), fmt_ms(s.p90), fmt_ms(s.mean), fmt_ms(s.max))


def targets(spec: PathSpec, calls: PathCalls, where: str) -> list[Target]:
    """The two latency targets of one path (``where``: e.g. ``"small, CPU"``)."""
    # The TPCNet path's names start like the ones docs/PERFORMANCE.md explains (bench.run_all's
    # MISS_NOTES, which are about DGGF, the head and decoding); the referent path's do not.
    if spec.key == "tpcnet":
        names = (
            f"`ground` median, {spec.label}, {where}",
            f"`encode_scene` + `ground` median, {spec.label}, {where}",
        )
    else:
        names = (
            f"Referent path: `ground` median, {where}",
            f"Referent path: `encode_scene` + `ground` median, {where}",
        )
    return [
        Target(names[0], median(calls.cached), GROUND_TARGET_MS, "ms", False),
        Target(names[1], median(calls.fresh), ENCODE_GROUND_TARGET_MS, "ms", False),
    ]


def side_by_side_table(
    title: str, specs: Sequence[PathSpec], calls: dict[str, PathCalls], models: dict[str, str]
) -> Table:
    """Both paths in one table (medians and p90s) with a Target row."""
    rows = []
    for spec in specs:
        c = calls[spec.key]
        cached, fresh = summarize(walls(c.cached)), summarize(walls(c.fresh))
        boxes = sum(x.boxes for x in c.cached) / len(c.cached)
        answer = sum(x.answer for x in c.cached) / len(c.cached)
        rows.append(
            (
                f"{spec.label} ({models[spec.key]})",
                str(cached.n),
                fmt_ms(cached.median),
                fmt_ms(cached.p90),
                fmt_ms(fresh.median),
                fmt_ms(fresh.p90),
                fmt_ms(median(c.repeated)),
                f"{boxes:.1f} / {answer:.1f}",
            )
        )
    rows.append(
        (
            "**Target** (issue 15)",
            "",
            f"<= {GROUND_TARGET_MS:g}",
            "",
            f"<= {ENCODE_GROUND_TARGET_MS:g}",
            "",
            "",
            "",
        )
    )
    return Table(
        title=title,
        columns=(
            "path (model)",
            "prompts",
            "`ground`, cached scene, median ms",
            "p90 ms",
            "`encode_scene` + `ground` median ms",
            "p90 ms",
            "prompt seen before, median ms",
            "boxes / answer per prompt",
        ),
        rows=tuple(rows),
        notes=(
            "`ground` on a scene encoded beforehand, every prompt new to the text encoder (its "
            "cache is off while timing); `encode_scene` + `ground` for a scene never seen; "
            "'prompt seen before': `ground` of a prompt already in the text cache.",
            "Boxes: returned by `ground` at its default threshold; answer: those at or above "
            "the model's operating threshold (`model.evaluation.predict.operating_threshold`).",
            "The paths take turns prompt by prompt, so that both see the same machine load.",
        ),
    )


def latency_table(title: str, calls: PathCalls) -> Table:
    """One path's three calls with count, median, p90, mean and max."""
    return Table(
        title=title,
        columns=LATENCY_COLUMNS,
        rows=(
            summary_row("`ground` on a cached scene", walls(calls.cached)),
            summary_row("`encode_scene` + `ground` (new scene)", walls(calls.fresh)),
            summary_row("`ground`, prompt seen before (text cache hit)", walls(calls.repeated)),
        ),
    )


def stage_table(
    title: str, calls: Sequence[Call], stages: Sequence[str], names: dict[str, str]
) -> Table:
    """Median, p90 and share of the mean per stage, the rest ("other") and the wall-clock total."""
    total_mean = summarize(walls(calls)).mean
    rows = []
    for k in stages:
        s = summarize([c.stages[k] for c in calls])
        share = 100.0 * s.mean / total_mean
        rows.append((names[k], fmt_ms(s.median), fmt_ms(s.p90), f"{share:.0f} %"))
    s = summarize([c.wall_ms - sum(c.stages[k] for k in stages) for c in calls])
    rows.append(("other (input checks, result packing)", fmt_ms(s.median), fmt_ms(s.p90), ""))
    s = summarize(walls(calls))
    rows.append(("**wall-clock total**", fmt_ms(s.median), fmt_ms(s.p90), "100 %"))
    return Table(
        title=title, columns=("stage", "median ms", "p90 ms", "share of mean"), rows=tuple(rows)
    )


def check_table(
    title: str,
    calls: Sequence[Call],
    outside: dict[str, list[float]],
    names: dict[str, str],
    how: str,
) -> Table:
    """The stages as ``ground`` reports them against the same stages timed from outside."""
    rows = []
    for k, samples in outside.items():
        mine = summarize(samples).median
        theirs = summarize([c.stages[k] for c in calls]).median
        rows.append((names[k], fmt_ms(theirs), fmt_ms(mine), fmt_ms(mine - theirs)))
    n = len(next(iter(outside.values())))
    return Table(
        title=title,
        columns=(
            "stage",
            "reported by `ground` (median ms)",
            "timed from outside (median ms)",
            "difference ms",
        ),
        rows=tuple(rows),
        notes=(f"Outside: {how} on the first {n} prompts.",),
    )


def detect_table(
    title: str, parts: dict[str, list[float]], reported: list[float], names: dict[str, str]
) -> Table:
    """The referent path's ``detect`` stage part by part (from outside) against the model's own
    ``SceneTimings.detect``."""
    rows = []
    for k, samples in parts.items():
        s = summarize(samples)
        rows.append((names[k], fmt_ms(s.median), fmt_ms(s.p90)))
    per_scene = [sum(v[i] for v in parts.values()) for i in range(len(reported))]
    s = summarize(per_scene)
    rows.append(("sum of the parts (timed from outside)", fmt_ms(s.median), fmt_ms(s.p90)))
    s = summarize(reported)
    rows.append(
        ("`SceneTimings.detect` reported by `encode_scene`", fmt_ms(s.median), fmt_ms(s.p90))
    )
    return Table(
        title=title,
        columns=("part", "median ms", "p90 ms"),
        rows=tuple(rows),
        notes=(
            f"{len(reported)} scenes; outside: the sensor branches and the fusion run through "
            "the model's public submodules, then the neck, the head, `decode` at the candidate "
            "threshold and `model.referent.candidates`, each timed.",
        ),
    )


def threads_table(title: str, data: dict[str, dict[int, list[float]]]) -> Table:
    """``ground`` and ``encode_scene`` + ``ground`` per torch thread count."""
    ground, total = data["ground_ms"], data["encode_ground_ms"]
    rows = tuple(
        (
            f"{t} thread{'s' if t > 1 else ''}",
            str(len(ground[t])),
            fmt_ms(summarize(ground[t]).median),
            fmt_ms(summarize(ground[t]).p90),
            fmt_ms(summarize(total[t]).median),
            fmt_ms(summarize(total[t]).p90),
        )
        for t in sorted(ground)
    )
    return Table(
        title=title,
        columns=(
            "torch threads",
            "prompts",
            "`ground` median ms",
            "`ground` p90 ms",
            "encode + ground median ms",
            "encode + ground p90 ms",
        ),
        rows=rows,
        notes=(
            "The two settings alternate prompt by prompt (text cache off), so both see the same "
            "machine load. The app runs with 1 thread (`launch.py --threads 1`).",
        ),
    )


def profile_table(title: str, rows: Sequence[ProfileRow]) -> Table:
    """A cProfile (see :func:`bench.perf.latency_measure.profile_calls`)."""
    return Table(
        title=title,
        columns=("function", "calls per call", "self ms per call", "cumulative ms per call"),
        rows=tuple(
            (r.where, f"{r.calls:.0f}", fmt_ms(r.self_ms), fmt_ms(r.cumulative_ms)) for r in rows
        ),
    )


def calls_data(spec: PathSpec, calls: PathCalls) -> dict:
    """The raw numbers of one path (JSON)."""
    scene = spec.scene_stages + spec.ground_stages
    return {
        "cached_ground_ms": walls(calls.cached),
        "encode_ground_ms": walls(calls.fresh),
        "repeated_ground_ms": walls(calls.repeated),
        "cached_stages_ms": {k: [c.stages[k] for c in calls.cached] for k in spec.ground_stages},
        "encode_stages_ms": {k: [c.stages[k] for c in calls.fresh] for k in scene},
        "boxes_per_prompt": [c.boxes for c in calls.cached],
        "answer_per_prompt": [c.answer for c in calls.cached],
    }
