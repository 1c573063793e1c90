"""The settings of a training run (:class:`TrainConfig`) and the command line that builds them.

``python -m model.train --help`` lists every option; docs/DESIGN.md and docs/REAL_DATA.md say
how they combine. :class:`TrainConfig` is stored in every checkpoint and run state.
"""

from __future__ import annotations

import argparse
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, get_args

import torch

from model.config import (
    AnchorKind,
    ClassSetName,
    FusionKind,
    GroundingKind,
    Modalities,
    PresetName,
    TextEncoderKind,
    TextFusionKind,
)
from model.config.sections import GroundKind
from model.training import threads as cpu_threads
from model.training.data import DataSpecError, RootSpec, root_specs
from scenes.language.prompts.sampling import FAMILIES, PromptConfig
from scenes.utils.cli import command_parser, from_args, option

AmpKind = Literal["none", "bf16"]
"""``--amp``: no autocast, or bfloat16 autocast of the forward passes (CUDA only)."""

LanguageKind = Literal["base", "extended"]
"""``--language``: the generated prompts' families (``scenes.language.prompts.PromptConfig.language``)."""

PhrasingKind = Literal["train", "heldout", "all"]
"""``--phrasing``: the generated prompts' wording variants (``scenes.language.prompts.phrasing``)."""


def default_device() -> str:
    """``cuda`` where CUDA is available, else ``cpu`` (the default of ``--device``)."""
    return "cuda" if torch.cuda.is_available() else "cpu"


LABEL_PROMPTS = 24
"""``--label-prompts`` when a root has scene labels and the flag is not given: prompts generated
per frame from its labelled boxes beside its given one (docs/RESULTS_HISTORY.md, "Real-format roots":
with 1,080 given prompts the referent stage learns the class and little more; with 24 such
prompts it learns the attributes)."""

LABELLED_PROMPTS_PER_SCENE = 4
"""``--prompts-per-scene`` when every root has scene labels and the flag is not given (a frame
holds its given prompt and :data:`LABEL_PROMPTS` more; measured beside the label prompts)."""

GENERATED_PROMPTS_PER_SCENE = 8
"""``--prompts-per-scene`` otherwise (prompts generated per scene and step)."""

TALK2CAR_PROMPTS_PER_SCENE = 16
"""``--prompts-per-scene`` when every root is a nuScenes root with Talk2Car commands and the flag
is not given: a sample holds several commands beside its :data:`LABEL_PROMPTS` label prompts, and
with 4 a step a command was drawn about 4 times in a 30-epoch ``--freeze-scene`` run (docs/
RESULTS_HISTORY.md, "Talk2Car on synthetic nuScenes roots": top-1 and the step's cost measured)."""

TALK2CAR_LABEL_PROMPTS = 96
"""The most ``--label-prompts`` a run on nuScenes roots with Talk2Car commands gets when the flag is
not given (:func:`talk2car_label_prompts`): a Talk2Car root of few samples teaches a referent stage
learnt from it (``--freeze-scene --init-detector``) more the more sentences about each sample it
reads: 96 label prompts a sample instead of :data:`LABEL_PROMPTS` gave 69.0 % top-1 against 68.0 %
on 2,125 val commands of another seed (docs/RESULTS_HISTORY.md, "Talk2Car on synthetic nuScenes roots"),
for about a minute more of prompt encoding."""

TALK2CAR_LABEL_BUDGET = 96 * 170
"""Label prompts a run on nuScenes roots generates in all (per view) by default: a root of 170
commanded samples gets :data:`TALK2CAR_LABEL_PROMPTS` a sample, one of more samples fewer (never
under :data:`TALK2CAR_MIN_LABEL_PROMPTS`), so the prompt encoding stays about a minute and a half
until the samples are many."""

TALK2CAR_MIN_LABEL_PROMPTS = 12
"""The fewest default label prompts a sample of a nuScenes root gets (:func:`talk2car_label_prompts`;
from 1,360 samples): a root of many samples holds its commands' sentences itself, and its label
prompts' generation and encoding grow with the samples (issue 48: 24 a sample on a root of 1,224
samples of one command each cost 2.5 minutes of a run that must stay within 20)."""


def talk2car_label_prompts(samples: int) -> int:
    """``--label-prompts`` of a run on nuScenes roots of ``samples`` commanded training samples in
    all: :data:`TALK2CAR_LABEL_BUDGET` shared among them, between
    :data:`TALK2CAR_MIN_LABEL_PROMPTS` and :data:`TALK2CAR_LABEL_PROMPTS` (96 for 170 samples, 48
    for 340, 16 for 1,000, 12 from 1,360)."""
    if samples <= 0:
        return TALK2CAR_LABEL_PROMPTS
    budget = TALK2CAR_LABEL_BUDGET // samples
    return int(min(TALK2CAR_LABEL_PROMPTS, max(TALK2CAR_MIN_LABEL_PROMPTS, budget)))


TALK2CAR_REFERENT_DROPOUT = 0.0
"""``--referent-dropout`` when every root is a nuScenes root with Talk2Car commands and the flag is
not given (the preset's ``ReferentConfig.dropout`` otherwise). A referent stage learnt on a
root's cached samples gains nothing from dropout inside its attention blocks, and dropout's random
masks are a third of a cached step's time on the CPU (docs/RESULTS_HISTORY.md, "Talk2Car on synthetic
nuScenes roots")."""


class TrainingError(RuntimeError):
    """Training cannot go on (bad data, non-finite loss); the message says why."""


@dataclass(frozen=True)
class PromptDraw:
    """The prompts the referent path generates per scene and step: what
    :meth:`TrainConfig.prompt_draw` makes of the run's flags (their one home is
    :class:`TrainConfig`; :class:`model.training.referent_step.ReferentTrainConfig` holds this).

    Attributes:
        per_scene: Prompts generated per scene and step (``--prompts-per-scene``).
        label_prompts: Labels-source frames with scene labels: prompts generated per frame from
            its labelled boxes, beside the given ones (``--label-prompts``).
        config: The generator's settings: ``--phrasing``, ``--language``, ``--text-noise`` (its
            ``p_perturb``), ``--command-share`` and ``--family-rate`` (:class:`scenes.language.prompts.PromptConfig`).
    """

    per_scene: int
    label_prompts: int = 0
    config: PromptConfig = field(default_factory=PromptConfig)


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """Everything that defines a training run (stored in the checkpoints). Each field is one flag
    of ``python -m model.train`` (:mod:`scenes.utils.cli`); ``on_resume`` marks the settings a resumed
    run may change (:data:`model.training.state.FREE_ON_RESUME`)."""

    data: tuple[str, ...] = option(
        help="Talk2Radar root; give it several times to train on several roots at once"
    )
    data_weights: tuple[float, ...] = option(
        (),
        flag="--data-weight",
        help="referent path: times each frame of the matching --data root (in order) is seen "
        "per epoch (default 1; a nuScenes root: model.training.data.talk2car_weight, an epoch "
        "visiting a sample per 2.4 training commands, at least 510 visits, at most 3 a sample)",
    )
    scene_labels: tuple[str, ...] = option(
        (),
        help="referent path: the View-of-Delft root whose label_2 lists every object of the "
        "matching --data root's frames (in order; 'none' for a root without); such a root trains "
        "on its labels and prompts only, never a sidecar",
    )
    talk2car: tuple[str, ...] = option(
        (),
        help="referent path: the Talk2Car command folder ({split}_commands.json) of the matching "
        "--data nuScenes root (in order; 'none' for a Talk2Radar root); its commands are the "
        "given prompts, every annotation of a commanded sample a detection target",
    )
    out: str = option(help="run folder, e.g. runs/NAME")
    preset: PresetName = option("small")
    epochs: int = option(
        20,
        on_resume=True,
        help="passes over the training data, each root's frames seen --data-weight times a "
        "pass (a nuScenes root: a visit per 2.4 commands; default 20)",
    )
    batch_size: int = option(4)
    lr: float = option(1e-3)
    weight_decay: float = option(5e-4)
    warmup_steps: int = option(50)
    modalities: Modalities | None = option(None)
    fusion: FusionKind | None = option(None)
    text_fusion: TextFusionKind | None = option(None)
    anchor: AnchorKind | None = option(None)
    text_encoder: TextEncoderKind | None = option(None)
    classes: ClassSetName = option(
        "vod",
        help="the class set the model detects and grounds (scenes.geometry.classes): vod (Car, "
        "Pedestrian, Cyclist) or nuscenes (nuScenes' 10 detection classes); labels of other "
        "classes are no targets",
    )
    referent_dropout: float | None = option(
        None,
        help="referent path: dropout inside the referent stage's attention blocks while training "
        f"(default: {TALK2CAR_REFERENT_DROPOUT} when every root is a nuScenes root with "
        "--talk2car, the preset's ReferentConfig.dropout otherwise)",
    )
    ground: GroundKind | None = option(
        None,
        help="referent path: heights measured from the sensor (sensor) or from the ground "
        "estimated from each LiDAR cloud (estimated: model.config.PillarConfig.ground), in "
        "training as at inference; default: the --init-detector or --init checkpoint's, else "
        "sensor",
    )
    grounding: GroundingKind = option(
        "referent",
        help="referent: text-agnostic detector + referent stage (default); tpcnet: the paper's "
        "DGGF + C3D-RECHead ranking",
    )
    init: str | None = option(
        None,
        on_resume=True,
        help="copy matching weights from this checkpoint before training (new runs)",
    )
    init_detector: str | None = option(
        None,
        on_resume=True,
        help="copy only the scene encoder and detector from this checkpoint; the referent stage "
        "starts from scratch, or from --init's when both are given (new runs)",
    )
    init_other_classes: str | None = option(
        None,
        on_resume=True,
        help="copy the weights of this checkpoint of another class set (e.g. the vod "
        "checkpoints/tpcnet-small.pt into a --classes nuscenes model): every weight whose shape "
        "matches; the class-shaped ones (heatmap channels, the referent stage's class columns) "
        "copied for the classes of both sets by name, the others re-initialised, as printed and "
        "recorded in the checkpoint (model.training.class_remap; new runs)",
    )
    prompts_per_scene: int | None = option(
        None,
        on_resume=True,
        help=f"referent path: prompts per scene and step (default {GENERATED_PROMPTS_PER_SCENE}; "
        f"{LABELLED_PROMPTS_PER_SCENE} when every root has --scene-labels, "
        f"{TALK2CAR_PROMPTS_PER_SCENE} when every root is a nuScenes root with --talk2car)",
    )
    radar_folder: str = option("auto", help="radar tree, 'auto' or 'none'")
    train_split: str = option("train", help="the split trained on (default train)")
    val_split: str = option("val", help="the split validated and calibrated on (default val)")
    val_every: int = option(1, on_resume=True, help="validate every N epochs (0: never)")
    val_limit: int = option(0, on_resume=True, help="validate on the first N frames only")
    seed: int = option(0)
    device: str = option(default_factory=default_device, on_resume=True)
    amp: AmpKind = option(
        "none",
        on_resume=True,
        help="bf16: bfloat16 autocast of the forward passes (CUDA only)",
    )
    max_steps: int = option(0, on_resume=True, help="stop after N steps (0: all epochs)")
    stop_epoch: int = option(
        0,
        on_resume=True,
        help="stop after this many epochs but keep the --epochs learning-rate schedule "
        "(a budget cut; --resume without it goes on)",
    )
    log_every: int = option(10, on_resume=True)
    flip_probability: float = option(0.5)
    sensor_augment: bool = option(
        True,
        help="referent path: no intensity / dropout / radar-count / single-scan augmentation",
    )
    freeze_scene: bool = option(
        False,
        help="referent path: train only the referent stage on scenes encoded once by the frozen "
        "detector (use with --init RUN/last.pt of a joint run)",
    )
    cache: str = option(
        "",
        on_resume=True,
        help="--freeze-scene: folder keeping the encoded scenes and prompt features for later "
        "runs (model.training.scene_store; default $TALK2PC_CACHE, else "
        "$XDG_CACHE_HOME/talk2pc, else ~/.cache/talk2pc; none: keep nothing)",
    )
    bank_prompts: int = option(
        24, on_resume=True, help="--freeze-scene: prompts generated and encoded once per scene"
    )
    given_variants: int = option(
        0,
        help="--freeze-scene, roots with given prompts (--scene-labels, --talk2car): rewordings "
        "of each given prompt banked beside it (scenes.language.prompts.noise.perturb: its "
        "meaning kept), default 0",
    )
    label_prompts: int | None = option(
        None,
        help="referent path, roots with --scene-labels or --talk2car: prompts generated per frame "
        "from its labelled boxes (class, depth and side; motion where the boxes' velocities are "
        f"known) beside the given ones (default {LABEL_PROMPTS} with --scene-labels, "
        f"up to {TALK2CAR_LABEL_PROMPTS} when every root is a nuScenes root: "
        "talk2car_label_prompts; 0: given prompts only)",
    )
    language: LanguageKind = option(
        "base",
        help="referent path: the generated prompts' families (scenes.language.prompts.PromptConfig."
        "language): base, or extended with things outside the classes and unsatisfiable "
        "attributes (the empty answer), negation, exclusion, ordinals, relations and counting",
    )
    phrasing: PhrasingKind = option(
        "train",
        help="referent path: the generated prompts' wording variants (scenes.language.prompts.phrasing): "
        "train (default; the held-out variants stay unseen, so a root written with --phrasing "
        "heldout measures new wording), heldout, or all",
    )
    text_noise: float = option(
        0.0,
        help="referent path: share of generated prompts reworded by scenes.language.prompts.perturb "
        "(filler-word dropout, synonyms, typos, casing; the meaning kept), default 0",
    )
    command_share: float = option(
        0.0,
        help="referent path: share of generated single-referent prompts phrased as driving "
        "commands around their description, Talk2Car style (scenes.language.prompts.commands; "
        "the referent kept), default 0",
    )
    people_share: float = option(
        0.0, help="referent path: share of those said as people do (prompts.people), default 0"
    )
    family_rates: tuple[float, ...] = option(
        (),
        flag="--family-rate",
        help="--language extended: the share of prompts of each non-attribute family, given "
        f"{len(FAMILIES) - 1} times in the order {', '.join(FAMILIES[1:])} (the attribute "
        "family gets the rest; default: scenes.language.prompts.sampling.EXTENDED_RATES)",
    )
    labelled_views: float = option(
        0.5,
        on_resume=True,
        help="--freeze-scene: share of scenes drawn as their labelled view (the frame's objects "
        "as labelled candidates with the label's class, the detector's other proposals as "
        "context: what --candidates labels and the app's labelled boxes ground over); 0: none "
        "cached (default 0.5)",
    )
    evidence_shift: float = option(
        0.5,
        on_resume=True,
        help="--freeze-scene: in a labelled view, share of labelled boxes that read another "
        "candidate's pooled detector features, so that the label decides the class "
        "(default 0.5)",
    )
    scene_limit: int = option(
        0, help="--freeze-scene: cache only the first N training scenes (0: all)"
    )
    calibrate: bool = option(
        True,
        negatable=True,
        on_resume=True,
        help="referent path: at the end of the run, choose the operating threshold on the first "
        "root's validation split (python -m model.calibrate) and store it in last.pt (default: "
        "on; a split with too few referred prompts leaves it uncalibrated, with a notice)",
    )
    grad_clip: float = option(35.0, cli=False)

    def __post_init__(self) -> None:
        for name in ("data", "data_weights", "scene_labels", "talk2car", "family_rates"):
            value = getattr(self, name)
            object.__setattr__(self, name, (value,) if isinstance(value, str) else tuple(value))
        try:
            roots = self.roots()
        except DataSpecError as exc:
            raise TrainingError(str(exc)) from exc
        labelled = [r.labelled for r in roots]
        talk2car = all(r.talk2car is not None for r in roots)
        if self.label_prompts is None:
            count = LABEL_PROMPTS if any(labelled) else 0
            if talk2car:
                count = talk2car_label_prompts(sum(r.samples or 0 for r in roots))
            object.__setattr__(self, "label_prompts", count)
        if self.prompts_per_scene is None:
            per_scene = LABELLED_PROMPTS_PER_SCENE if all(labelled) else GENERATED_PROMPTS_PER_SCENE
            if talk2car:
                per_scene = TALK2CAR_PROMPTS_PER_SCENE
            object.__setattr__(self, "prompts_per_scene", per_scene)
        if self.referent_dropout is None and talk2car:
            object.__setattr__(self, "referent_dropout", TALK2CAR_REFERENT_DROPOUT)
        if self.referent_dropout is not None and not 0.0 <= self.referent_dropout < 1.0:
            raise TrainingError(
                f"--referent-dropout must be in [0, 1), got {self.referent_dropout}"
            )
        if self.given_variants < 0:
            raise TrainingError(f"--given-variants must be >= 0, got {self.given_variants}")
        if self.label_prompts < 0:
            raise TrainingError(f"--label-prompts must be >= 0, got {self.label_prompts}")
        given = [n for n in ("init", "init_detector", "init_other_classes") if getattr(self, n)]
        if len(given) > 1 and given != ["init", "init_detector"]:
            flags = " and ".join("--" + n.replace("_", "-") for n in given)
            raise TrainingError(
                "give one of --init, --init-detector, --init-other-classes (or --init with "
                f"--init-detector), not {flags}"
            )
        for name in ("epochs", "batch_size", "prompts_per_scene"):
            if getattr(self, name) < 1:
                flag = "--" + name.replace("_", "-")
                raise TrainingError(f"{flag} must be >= 1, got {getattr(self, name)}")
        if self.amp not in ("none", "bf16"):
            raise TrainingError(f"--amp must be none or bf16, got {self.amp!r}")
        for name, kind in (("language", LanguageKind), ("phrasing", PhrasingKind)):
            choices, value = get_args(kind), getattr(self, name)
            if value not in choices:
                allowed = ", ".join(choices[:-1]) + " or " + choices[-1]
                raise TrainingError(f"--{name} must be {allowed}, got {value!r}")
        if self.family_rates:
            if self.language != "extended":
                raise TrainingError("--family-rate is --language extended's")
            try:  # the generator's own rule for the shares (one home)
                PromptConfig(language="extended", family_rates=self.family_rates)
            except ValueError as exc:
                raise TrainingError(
                    f"--family-rate (given once per family: {', '.join(FAMILIES[1:])}): {exc}"
                ) from exc
        for name in ("text_noise", "command_share", "people_share"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                flag = "--" + name.replace("_", "-")
                raise TrainingError(f"{flag} must be in [0, 1], got {getattr(self, name)}")
        if self.grounding not in get_args(GroundingKind):
            kinds = " or ".join(get_args(GroundingKind))
            raise TrainingError(f"--grounding must be {kinds}, got {self.grounding!r}")
        if self.classes not in get_args(ClassSetName):
            raise TrainingError(
                f"--classes must be one of {get_args(ClassSetName)}, got {self.classes!r}"
            )
        if Path(self.out).exists() and not Path(self.out).is_dir():
            raise TrainingError(f"--out {self.out} is a file; give a run folder")

    def roots(self) -> tuple[RootSpec, ...]:
        """The training roots (:func:`model.training.data.root_specs`)."""
        return root_specs(self.data, self.data_weights, self.scene_labels, self.talk2car)

    def prompt_draw(self) -> PromptDraw:
        """The referent path's prompts of these settings (the one place the flags are mapped to
        the generator's)."""
        rates = {"family_rates": self.family_rates} if self.family_rates else {}
        config = PromptConfig(
            phrasing=self.phrasing,
            language=self.language,
            p_perturb=self.text_noise,
            command_share=self.command_share,
            people_share=self.people_share,
            **rates,
        )
        return PromptDraw(self.prompts_per_scene, self.label_prompts, config)

    def model_overrides(self) -> dict[str, object]:
        """The ``build_model`` overrides given on the command line."""
        names = (
            "modalities", "fusion", "text_fusion", "anchor", "text_encoder", "grounding", "classes"
        )  # fmt: skip
        out = {n: getattr(self, n) for n in names if getattr(self, n) is not None}
        if self.referent_dropout is not None:
            out["referent__dropout"] = self.referent_dropout
        if self.ground is not None:
            out["pillars__ground"] = self.ground
        return out


@dataclass(frozen=True, kw_only=True)
class TrainCommand:
    """The flags of ``python -m model.train`` that are not a run's settings (:class:`TrainConfig`).

    Attributes:
        resume: Continue the run in ``--out``.
        threads: torch's CPU threads (0: :func:`model.training.threads.freeze_scene_threads` for a ``--freeze-scene``
            run on the CPU, torch's default otherwise).
    """

    resume: bool = option(False, help="continue the run in --out")
    threads: int = option(
        0,
        help="torch CPU threads (0: for --freeze-scene on the CPU, every core on an idle machine "
        "and 1 on a busy one; torch's default otherwise); use 1 when other jobs share the cores",
    )


def build_parser() -> argparse.ArgumentParser:
    """``python -m model.train``'s parser: :class:`TrainConfig`'s flags, then
    :class:`TrainCommand`'s."""
    return command_parser(
        "python -m model.train", __doc__.split("\n")[0], TrainConfig, TrainCommand
    )


def parse_args(argv: list[str] | None = None) -> tuple[TrainConfig, bool]:
    """Parse the command line into a :class:`TrainConfig` and the resume flag."""
    a = build_parser().parse_args(argv)
    command = from_args(TrainCommand, a)
    cfg = from_args(TrainConfig, a)
    threads = command.threads
    if not threads and cfg.freeze_scene and str(cfg.device).startswith("cpu"):
        ranks = int(os.environ.get("LOCAL_WORLD_SIZE", "1") or 1)  # torchrun's, on this machine
        load = cpu_threads.machine_load()
        threads = cpu_threads.freeze_scene_threads(load, os.cpu_count() or 1, ranks)
    if threads:
        torch.set_num_threads(threads)
    return cfg, command.resume


__all__ = [
    "GENERATED_PROMPTS_PER_SCENE",
    "LABELLED_PROMPTS_PER_SCENE",
    "LABEL_PROMPTS",
    "TALK2CAR_LABEL_BUDGET",
    "TALK2CAR_LABEL_PROMPTS",
    "TALK2CAR_MIN_LABEL_PROMPTS",
    "TALK2CAR_PROMPTS_PER_SCENE",
    "TALK2CAR_REFERENT_DROPOUT",
    "PromptDraw",
    "TrainConfig",
    "TrainingError",
    "parse_args",
    "talk2car_label_prompts",
]
