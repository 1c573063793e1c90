"""The adaptation run: rounds of pseudo-labelling and training (``python -m model.adapt``).

Round ``r`` (the curriculum's :meth:`model.adapt.config.AdaptConfig.round_plan`):

1. **Pseudo-labels** (:func:`label_frames`): the current detector (eval mode, no augmentation)
   on every frame; boxes at or above their class's ignore threshold merged into the frame's
   memory (:func:`model.adapt.pseudo.ensemble`; each first rested on the ground around it,
   :func:`model.adapt.pseudo.seat_on_ground`), then split into pseudo-labels and ignored boxes
   (:func:`model.adapt.pseudo.partition`). The round's report entry counts them per class.
2. **Training** (:func:`train_step`, ``--steps-per-round`` steps): batches of frames drawn from
   ``(seed, round, pass)`` permutations, each frame under its own random view
   (:mod:`model.adapt.augment`: flip, rotation, scaling, the pseudo-labels transformed with the
   cloud), the detector's targets of the pseudo-labels with no negatives on the ignored boxes
   (:func:`model.training.referent_step.detection_targets`) and its loss
   (:func:`model.head.losses.grounding_loss`); AdamW with the training command's cosine schedule
   (:func:`model.training.loop.cosine_lr`) over all the run's steps and its gradient clipping.

Only the scene encoder and the detector (``lidar.``, ``radar.``, ``fusion.``, ``neck.``,
``head.``) are trained; they run in train mode but for their batch-norm layers, whose running
statistics stay the initial checkpoint's (``--norm-statistics keep``; ``follow``: they follow the
new sensor's frames, AdaBN-like, which on two-frame batches cost more than it gave:
docs/RESULTS.md, "Adaptation to unlabelled frames"). The text encoder and the referent stage are
frozen and in eval mode: the adapted checkpoint answers prompts with the initial checkpoint's referent stage over the
adapted detector's candidates, at the initial checkpoint's operating threshold.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from model.adapt.augment import draw_view
from model.adapt.config import AdaptConfig, AdaptError, RoundPlan
from model.adapt.frames import SensorFrame, UnlabelledFrames
from model.adapt.pseudo import (
    FrameMemory,
    FrameTargets,
    ensemble,
    partition,
    positive_mask,
    seat_on_ground,
    select,
)
from model.adapt.state import (
    LAST_FILE,
    REPORT_FILE,
    Progress,
    RunFiles,
    adapted_meta,
    load_state,
    model_payload,
    round_file,
    save_state,
)
from model.checkpoint import CheckpointError, model_from_payload, read_checkpoint, write_payload
from model.head.decode import decode
from model.head.losses import LossTerms, grounding_loss
from model.tpcnet import TPCNet
from model.training.loop import cosine_lr
from model.training.referent_step import detection_targets, float32_output, in_grid_actors
from model.training.state import rng_state, set_rng_state
from model.training.stop_signal import StopRequest, TrainingInterrupted
from scenes.datasets.frames import FrameItem
from scenes.geometry.actors import Actor
from scenes.utils.durable import atomic_write_text


@dataclass
class AdaptRun:
    """A run under way (what :func:`set_up` made)."""

    cfg: AdaptConfig
    frames: UnlabelledFrames
    model: TPCNet
    params: list[torch.nn.Parameter]
    optimizer: torch.optim.Optimizer
    files: RunFiles
    out: Path
    targets: dict[str, FrameTargets] = field(default_factory=dict)

    @property
    def progress(self) -> Progress:
        return self.files.progress

    def save(self) -> None:
        """The state as it is now (:func:`model.adapt.state.save_state`)."""
        meta = adapted_meta(self.files.init_meta, self.cfg, self.progress.round)
        self.files.model = model_payload(self.model, meta)
        self.files.optimizer = self.optimizer.state_dict()
        self.files.rng = rng_state()
        save_state(self.out, self.cfg, self.files)


def load_init(path: str, device: torch.device) -> TPCNet:
    """The checkpoint to adapt (:class:`AdaptError` in one line: missing, corrupt, another
    format, or a paper-path checkpoint, whose detector is conditioned on the text)."""
    try:
        model = model_from_payload(read_checkpoint(path), path, device)
    except CheckpointError as exc:
        raise AdaptError(f"--init: {exc}") from exc
    if not model.takes_labelled_candidates:  # the referent path's head: a text-agnostic detector
        raise AdaptError(
            f"--init {path}: a {model.cfg.grounding!r} checkpoint; adaptation needs a "
            "referent-path checkpoint (its detector is text-agnostic)"
        )
    return model


def set_up(cfg: AdaptConfig) -> AdaptRun:
    """The frames, the model (the saved run's, or ``--init``), the optimiser and the state."""
    out = Path(cfg.out)
    device = torch.device(cfg.device)
    frames = UnlabelledFrames(cfg.data, cfg.radar_folder, cfg.split, cfg.max_frames)
    files = load_state(out, cfg)
    if files is None:
        model = load_init(cfg.init, device)
        init_meta = model.checkpoint_metadata.to_dict()
        files = RunFiles({}, {}, Progress(), {}, [], init_meta, None)
    else:
        model = model_from_payload(files.model, out, device)
        print(
            f"{out}: resuming after {files.progress.round} rounds "
            f"(step {files.progress.step_in_round} of round {files.progress.round + 1})",
            file=sys.stderr,
        )
    cfg.thresholds(model.cfg.class_set.names)  # an override of a class the checkpoint lacks
    pillars = model.cfg.pillars
    if pillars.levels_on_ground:  # the frames as the model sees them at inference
        frames.ground_height = pillars.ground_height
    scene = {id(p) for p in model.scene.parameters()}
    params = [p for p in model.parameters_in_checkpoint_order() if id(p) in scene]
    for p in model.parameters():
        p.requires_grad_(id(p) in scene)
    optimizer = torch.optim.AdamW(params, lr=cfg.lr, weight_decay=cfg.weight_decay)
    if files.optimizer:
        optimizer.load_state_dict(files.optimizer)
    if files.rng is not None:
        set_rng_state(files.rng)
    else:
        torch.manual_seed(cfg.seed)
    return AdaptRun(cfg, frames, model, params, optimizer, files, out)


BATCH_NORMS = (torch.nn.BatchNorm1d, torch.nn.BatchNorm2d, torch.nn.BatchNorm3d)
"""The layers whose running statistics ``--norm-statistics keep`` holds."""


def detect_frames(
    model: TPCNet, frames: list[SensorFrame], threshold: float
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The detector's ``(boxes (K, 7), labels (K,), scores (K,))`` of each frame at
    ``threshold`` (eval mode, no gradient)."""
    model.eval()
    with torch.no_grad():
        lidar = model.scene.clouds([f.lidar for f in frames], len(frames), "lidar")
        radar = model.scene.clouds([f.radar for f in frames], len(frames), "radar")
        out, _ = model.detect(lidar, radar)
        dets = decode(float32_output(out), model.head_grid, model.cfg.head, threshold)
    return [(d.boxes, d.labels, d.scores) for d in dets]


def label_frames(run: AdaptRun, plan: RoundPlan, stop: StopRequest) -> dict[str, Any]:
    """Step 1 of a round (module docstring): the memory updated, the round's targets and its
    report entry (per class: pseudo-labels, ignored boxes, their mean score; the merge's counts)."""
    cfg, files = run.cfg, run.files
    floor = min(plan.negative.values())
    merged = {"matched": 0, "added": 0, "missed": 0, "dropped": 0}
    bar = tqdm(
        range(len(run.frames)),
        desc=f"round {plan.index + 1} labels",
        unit="frame",
        disable=cfg.quiet,
        dynamic_ncols=True,
        leave=False,
    )
    for i in bar:
        frame = run.frames[i]
        if stop.signum:
            raise TrainingInterrupted(
                stop.signum,
                f"stopped while making round {plan.index + 1}'s pseudo-labels; the state of "
                f"{run.progress.round} finished rounds is kept: run the same command again",
            )
        boxes, labels, scores = detect_frames(run.model, [frame], floor)[0]
        if cfg.seat_on_ground:
            boxes = seat_on_ground(boxes, frame.lidar)
        keep = select(labels, scores, plan.negative, plan.classes)
        memory = files.memory.get(frame.sample_id, FrameMemory.empty())
        memory, stats = ensemble(
            memory, boxes[keep], labels[keep], scores[keep], cfg.memory_iou, cfg.max_miss
        )
        files.memory[frame.sample_id] = memory
        for key in merged:
            merged[key] += getattr(stats, key)
    entry: dict[str, Any] = plan.to_dict()
    entry.update(frames=len(run.frames), memory=merged)
    entry.update(count_targets(files.memory, plan))
    entry.update(steps=0, loss=0.0, heatmap=0.0, regression=0.0)
    return entry


def count_targets(memory: dict[str, FrameMemory], plan: RoundPlan) -> dict[str, Any]:
    """Per class: pseudo-labels, ignored boxes and the pseudo-labels' mean score."""
    positive = dict.fromkeys(plan.classes, 0)
    ignored = dict.fromkeys(plan.classes, 0)
    score_sum = dict.fromkeys(plan.classes, 0.0)
    for m in memory.values():
        mask = positive_mask(m, plan)
        for label, score, kept in zip(m.labels, m.scores, mask, strict=True):
            name = plan.classes[label]
            if kept:
                positive[name] += 1
                score_sum[name] += float(score)
            else:
                ignored[name] += 1
    mean = {
        c: (round(score_sum[c] / positive[c], 4) if positive[c] else None) for c in plan.classes
    }
    return {"pseudo_labels": positive, "ignored": ignored, "mean_score": mean}


def step_indices(n: int, batch: int, seed: int, round_index: int, step: int) -> list[int]:
    """The frames of a step: consecutive ``batch`` items of the round's passes over the ``n``
    frames, each pass a permutation seeded by ``(seed, round, pass)``."""
    out = []
    for position in range(step * batch, (step + 1) * batch):
        order = np.random.default_rng((seed, round_index, position // n)).permutation(n)
        out.append(int(order[position % n]))
    return out


def train_step(run: AdaptRun, plan: RoundPlan, step: int) -> LossTerms:
    """One optimiser step of round ``plan.index`` (module docstring, step 2)."""
    cfg, model = run.cfg, run.model
    global_step = plan.index * cfg.steps_per_round + step
    for group in run.optimizer.param_groups:
        group["lr"] = cosine_lr(
            global_step, cfg.rounds * cfg.steps_per_round, cfg.lr, cfg.warmup_steps
        )
    items = []
    for b, index in enumerate(
        step_indices(len(run.frames), cfg.batch_size, cfg.seed, plan.index, step)
    ):
        frame = run.frames[index]
        rng = np.random.default_rng((cfg.seed, 31, plan.index, step, b))
        view = draw_view(rng, cfg.flip_probability, cfg.max_rotation, cfg.scale_range)
        t = run.targets[frame.sample_id]
        actors = tuple(
            Actor(k, plan.classes[label], box, np.zeros(2))
            for k, (box, label) in enumerate(zip(view.boxes(t.boxes), t.labels, strict=True))
        )
        items.append(
            FrameItem(
                frame.sample_id,
                view.points(frame.lidar),
                view.points(frame.radar),
                actors,
                ignore_boxes=view.boxes(t.ignore),
            )
        )
    model.train()
    model.text_encoder.eval()
    model.grounding.eval()
    if cfg.norm_statistics == "keep":
        for module in model.scene.modules():
            if isinstance(module, BATCH_NORMS):
                module.eval()
    lidar = model.scene.clouds([f.lidar for f in items], len(items), "lidar")
    radar = model.scene.clouds([f.radar for f in items], len(items), "radar")
    out, _ = model.detect(lidar, radar)
    actors = [in_grid_actors(f.actors, model) for f in items]
    targets = detection_targets(model, items, actors).to(model.device)
    terms = grounding_loss(float32_output(out), targets, beta=cfg.regression_weight)
    run.optimizer.zero_grad(set_to_none=True)
    terms.total.backward()
    norm = torch.nn.utils.clip_grad_norm_(run.params, cfg.grad_clip)
    if not (torch.isfinite(terms.total) and torch.isfinite(norm)):
        raise AdaptError(
            f"non-finite loss or gradient at round {plan.index + 1} step {step}; "
            f"{run.out / LAST_FILE} keeps the last good weights"
        )
    run.optimizer.step()
    return terms


def finish_round(run: AdaptRun) -> None:
    """After a round: progress, the state, ``round<k>.pt``, ``last.pt`` and the report."""
    run.progress.round += 1
    run.progress.step_in_round = 0
    run.save()
    payload = run.files.model
    write_payload(run.out / round_file(run.progress.round), payload)
    write_payload(run.out / LAST_FILE, payload)
    write_report(run)


def write_report(run: AdaptRun) -> None:
    """``RUN/adapt_report.json``: the settings and one entry per round."""
    text = json.dumps({"settings": run.cfg.settings(), "rounds": run.files.report}, indent=2)
    atomic_write_text(run.out / REPORT_FILE, text + "\n")


def report_table(report: list[dict[str, Any]]) -> str:
    """The report as a text table: per round, the thresholds, range, pseudo-labels and ignored
    boxes per class (the classes the rounds name), the memory merge and the mean training loss."""
    classes = list(report[0]["positive"]) if report else []
    head = ["round", "range m"]
    short = [c[:4] for c in classes]  # Trailer and TrafficCone differ in their fourth letter
    head += [f"thr {c}" for c in short] + [f"pseudo {c}" for c in short]
    head += [f"ign {c}" for c in short] + ["matched", "added", "dropped", "loss"]
    rows = [head]
    for e in report:
        row = [str(e["round"] + 1), f"{e['max_range']:.0f}"]
        row += [f"{e['positive'][c]:.2f}" for c in classes]
        row += [str(e["pseudo_labels"][c]) for c in classes]
        row += [str(e["ignored"][c]) for c in classes]
        m = e["memory"]
        row += [str(m["matched"]), str(m["added"]), str(m["dropped"])]
        row.append(f"{e['loss']:.3f}" if e["steps"] else "-")
        rows.append(row)
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows)


def adapt(cfg: AdaptConfig) -> list[dict[str, Any]]:
    """Run (or continue) the adaptation; returns the report (one entry per round begun).

    Raises:
        AdaptError: bad settings, root or checkpoint (one line).
        TrainingInterrupted: SIGINT / SIGTERM (the state is saved: run again to continue).
    """
    run = set_up(cfg)
    total = cfg.rounds * cfg.steps_per_round
    done = run.progress.round * cfg.steps_per_round + run.progress.step_in_round
    bar = tqdm(
        total=total, initial=done, desc="adapt", unit="step", disable=cfg.quiet, dynamic_ncols=True
    )
    with StopRequest() as stop, stop.deferred():
        while run.progress.round < cfg.rounds:
            if cfg.stop_after_round and run.progress.round >= cfg.stop_after_round:
                break
            r = run.progress.round
            plan = cfg.round_plan(r, run.model.cfg.class_set.names)
            if run.progress.labelled_round < r:
                run.files.report = [*run.files.report[:r], label_frames(run, plan, stop)]
                run.progress.labelled_round = r
                run.save()
            run.targets = {sid: partition(m, plan) for sid, m in run.files.memory.items()}
            entry = run.files.report[r]
            while run.progress.step_in_round < cfg.steps_per_round:
                if stop.signum:
                    run.save()
                    bar.close()
                    raise TrainingInterrupted(
                        stop.signum,
                        f"stopped in round {r + 1} after step {run.progress.step_in_round}; "
                        f"run the same command again to continue ({run.out})",
                    )
                terms = train_step(run, plan, run.progress.step_in_round)
                run.progress.step_in_round += 1
                steps = entry["steps"]
                for key, value in (
                    ("loss", terms.total),
                    ("heatmap", terms.heatmap),
                    ("regression", terms.regression),
                ):
                    entry[key] = (entry[key] * steps + value.item()) / (steps + 1)
                entry["steps"] = steps + 1
                bar.update(1)
                bar.set_postfix(round=r + 1, loss=f"{terms.total.item():.3f}")
            finish_round(run)
            bar.write(_round_line(entry))
    bar.close()
    if run.files.report:
        write_report(run)
    return run.files.report


def _round_line(entry: dict[str, Any]) -> str:
    counts = ", ".join(f"{c} {n}" for c, n in entry["pseudo_labels"].items())
    return (
        f"round {entry['round'] + 1}: pseudo-labels {counts} (within {entry['max_range']:.0f} m); "
        f"mean loss {entry['loss']:.3f}"
    )


__all__ = ["AdaptRun", "adapt", "detect_frames", "label_frames", "report_table", "step_indices"]
