"""The language suite: a checkpoint on sentences people type, per family, beside baselines.

``python -m bench.language_suite --checkpoint checkpoints/tpcnet-small.pt [--scenes DIR]
[--json docs/results/language-suite.json]`` generates the suite's fixed scenes when missing
(:mod:`bench.studies.language_cases`), checks their fingerprint, encodes each scene once
(``TPCNet.encode_scene``) and grounds every case as the app does (the prompt through
:func:`scenes.utils.text_policy.clean_text`, ``TPCNet.ground``, the checkpoint's calibrated operating
threshold for the answer set), then prints one markdown table: per family and figure
(:mod:`bench.studies.language_score`) the model, the same model given only the class noun ("the cars";
"the objects" where no class is named) and the language-blind oracle (every referable actor of the
named class, score 1). Rewording cases are also grounded in the generator's own wording of the
same meaning where it has one (:mod:`bench.studies.language_generator`), on the same cases.

Model imports: only the public ``model`` names ``class_noun_prompt`` (the baseline's prompt, the
same as ``model.evaluate``'s), ``load_checkpoint`` and ``operating_threshold`` (the CLI); the rest
takes any object with ``encode_scene`` / ``ground`` as the app does.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from bench.studies.language_cases import (
    DEFAULT_SCENES,
    SUITE_FILE,
    Case,
    Suite,
    build_cases,
    check_fingerprint,
    ensure_scenes,
    fingerprint,
    load_suite,
    scene_actors,
    write_fingerprint,
)
from bench.studies.language_generator import generator_sentence
from bench.studies.language_score import (
    Answer,
    Outcome,
    family_figures,
    format_table,
    oracle_outcome,
    score,
)
from model import class_noun_prompt
from scenes.language.resolve import referable
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.utils.cli import command_parser, option, run_command
from scenes.utils.durable import atomic_write_text
from scenes.utils.text_policy import PROMPT, clean_text

REWORDING = "rewording"
GENERATOR_COLUMNS = ("rewording, same cases", "generator wording")


@dataclass
class SuiteReport:
    """What a run measured: per column (answerer) the family figures, and per sentence its
    model outcomes."""

    threshold: float
    columns: dict[str, dict[str, dict[str, float | int]]]
    rewording_pairs: dict[str, dict[str, float | int]]
    per_sentence: dict[str, dict[str, float | int | str]] = field(default_factory=dict)
    seconds: float = 0.0

    def table(self) -> str:
        """The markdown tables (the families; the rewording against the generator's wording)."""
        text = format_table(self.columns)
        if self.rewording_pairs.get(GENERATOR_COLUMNS[0], {}).get("cases"):
            cols = {n: {REWORDING: v} for n, v in self.rewording_pairs.items()}
            text += "\n" + format_table(cols)
        return text

    def to_dict(self) -> dict:
        return {
            "threshold": self.threshold,
            "families": self.columns,
            "rewording_vs_generator_wording": self.rewording_pairs,
            "per_sentence": self.per_sentence,
            "seconds": self.seconds,
        }


def _ground(model: object, features: object, text: str) -> Answer:
    pred = model.ground(features, clean_text(text, PROMPT))  # type: ignore[attr-defined]
    return Answer.of(pred.boxes, tuple(pred.classes), pred.scores)


def run_suite(
    model: object,
    suite: Suite,
    root: Talk2RadarRoot,
    threshold: float,
    progress: bool = True,
    max_scenes: int | None = None,
) -> SuiteReport:
    """Ground every case of ``suite`` on ``root``'s scenes with ``model`` (eval mode, no gradient)
    and score it at ``threshold``; the scenes' fingerprint must match the suite's."""
    start = time.perf_counter()
    check_fingerprint(suite, root)
    cases = build_cases(suite, root) if max_scenes is None else build_cases(suite, root, max_scenes)
    by_scene: dict[str, list[Case]] = defaultdict(list)
    for case in cases:
        by_scene[case.sample_id].append(case)
    outcomes: dict[str, list[tuple[str, Outcome]]] = defaultdict(list)
    sentence_rows: dict[str, list[Outcome]] = defaultdict(list)
    if hasattr(model, "eval"):
        model.eval()  # type: ignore[attr-defined]
    bar = tqdm(total=len(cases), desc="language suite", unit="case", disable=not progress)
    with torch.no_grad(), bar:
        for sid in sorted(by_scene):
            sample = root.load(sid)
            actors = scene_actors(root, sid)
            by_id = {a.actor_id: a for a in actors}
            features = model.encode_scene(sample.lidar, sample.radar)  # type: ignore[attr-defined]
            nouns: dict[str, Answer] = {}
            for case in by_scene[sid]:
                fam, query = case.sentence.family, case.sentence.query
                ref_boxes = np.array([by_id[i].box for i in case.referents]).reshape(-1, 7)
                ref_cls = [by_id[i].cls for i in case.referents]
                mine = score(
                    _ground(model, features, case.sentence.text), ref_boxes, ref_cls, threshold
                )
                outcomes["model"].append((fam, mine))
                sentence_rows[case.sentence.id].append(mine)
                noun = class_noun_prompt(query.cls)
                if noun not in nouns:
                    nouns[noun] = _ground(model, features, noun)
                outcomes["class noun"].append(
                    (fam, score(nouns[noun], ref_boxes, ref_cls, threshold))
                )
                named = [a for a in actors if referable(a) and query.cls in (None, a.cls)]
                outcomes["oracle"].append((fam, oracle_outcome(len(named), len(case.referents))))
                if fam == REWORDING:
                    key = f"{case.sentence.id}/{sid}"
                    text = generator_sentence(query, actors, case.referents, key)
                    if text is not None:
                        theirs = score(
                            _ground(model, features, text), ref_boxes, ref_cls, threshold
                        )
                        outcomes[GENERATOR_COLUMNS[0]].append((fam, mine))
                        outcomes[GENERATOR_COLUMNS[1]].append((fam, theirs))
                bar.update(1)
    columns = {n: family_figures(outcomes[n]) for n in ("model", "class noun", "oracle")}
    pairs = {n: family_figures(outcomes[n])[REWORDING] for n in GENERATOR_COLUMNS}
    per_sentence: dict[str, dict[str, float | int | str]] = {}
    for s in suite.sentences:
        rows = sentence_rows.get(s.id, [])
        per_sentence[s.id] = {
            "family": s.family,
            "text": s.text,
            "cases": len(rows),
            **{
                k: round(100.0 * float(np.mean([o.figure(k) for o in rows])), 1) if rows else 0.0
                for k in ("empty", "top1", "f1", "exact")
            },
        }
    return SuiteReport(threshold, columns, pairs, per_sentence, time.perf_counter() - start)


@dataclass(frozen=True, kw_only=True)
class LanguageSuiteOptions:
    """The flags of ``python -m bench.language_suite``."""

    checkpoint: Path = option(Path("checkpoints/tpcnet-small.pt"))
    scenes: Path = option(DEFAULT_SCENES, help="the suite's scenes folder")
    suite: Path = option(SUITE_FILE, help="the suite file")
    json: Path | None = option(None, help="write the figures here")
    threshold: float | None = option(None, help="default: the checkpoint's")
    device: str = option("cpu")
    write_fingerprint: bool = option(
        False,
        help="record the scenes under --scenes as the suite's (after a deliberate generator change)",
    )


def build_parser() -> argparse.ArgumentParser:
    return command_parser(
        "python -m bench.language_suite",
        "Ground the hand-written language suite with a checkpoint; per-family figures.",
        LanguageSuiteOptions,
    )


def run(args: LanguageSuiteOptions) -> int:
    """Run the suite as ``args`` says (or record its scenes' fingerprint) and print the table
    (errors raise)."""
    suite = load_suite(args.suite)
    root = ensure_scenes(suite, args.scenes)
    if args.write_fingerprint:
        write_fingerprint(args.suite, fingerprint(root))
        print(f"{args.suite}: recorded the fingerprint of {args.scenes}")
        return 0
    from model import load_checkpoint

    model = load_checkpoint(args.checkpoint, device=args.device)
    if args.threshold is None:
        from model import operating_threshold

        threshold = operating_threshold(model)  # type: ignore[arg-type]
    else:
        threshold = float(args.threshold)
    report = run_suite(model, suite, root, threshold)
    print(
        f"language suite {args.suite} ({len(suite.sentences)} sentences) on {args.scenes}; "
        f"checkpoint {args.checkpoint}; operating threshold {threshold:g}; "
        f"{report.seconds:.0f} s"
    )
    print(report.table(), end="")
    if args.json is not None:
        atomic_write_text(args.json, json.dumps(report.to_dict(), indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m bench.language_suite``; a bad suite, root or checkpoint (SuiteError and the
    others are ValueErrors) is one ``error:`` line, exit status 2."""
    return run_command(build_parser(), LanguageSuiteOptions, run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
