"""Talk2Radar-style referring prompts whose referents are known exactly.

A prompt is generated from a :class:`Predicate`, a small conjunction over the actors of a frame:
an optional class (``Car``, ``Pedestrian``, ``Cyclist``; ``None`` = any class, "objects"), at most
one atom per family (position :class:`OnSide`, motion :class:`MotionState`, heading
:class:`HeadingIs`, speed :class:`SpeedAbout` / :class:`SpeedAbove` / :class:`SpeedBelow`, depth
:class:`DepthAbout` / :class:`DepthBetween` / :class:`DepthWithin` / :class:`DepthBeyond`) and an
optional superlative (:class:`Extreme`). :func:`resolve` evaluates it over all referable actors
and the sentence is rendered afterwards from the size of the resolved set, so a stated count
always equals the number of referents.

Modules, in import order (each imports only those above it):

* :mod:`~scenes.prompts.tags` -- keyword type tags (:func:`infer_tags`) and :func:`flip_left_right`,
  for any text, generated or typed.
* :mod:`~scenes.prompts.features` -- :class:`ActorFeatures` and the :class:`ReferableRegion`.
* :mod:`~scenes.prompts.atoms` -- the atoms, superlatives and their exact semantics.
* :mod:`~scenes.prompts.predicate` -- :class:`Predicate`, :func:`analyse`, :func:`resolve`,
  ambiguity and crispness.
* :mod:`~scenes.prompts.numbers` -- numbers in digits or words.
* :mod:`~scenes.prompts.phrasing` -- the phrasing variant tables and their train / held-out split.
* :mod:`~scenes.prompts.render` -- :class:`Prompt` and :func:`render` (predicate -> sentence).
* :mod:`~scenes.prompts.generate` -- :class:`PromptConfig` and :func:`generate_prompts`.
* :mod:`~scenes.prompts.describe` -- :func:`describe` (a sentence for a given set of actors).

Type tags (``class``, ``depth``, ``velocity``, ``motion``, ``position``, the TPCNet paper's table
III types) follow the predicate, and every phrasing is written so that :func:`infer_tags` (which
also serves real Talk2Radar prompts) gives the same tags from the text.
"""

from scenes.prompts.atoms import (
    ABOUT_DEPTH_TOL,
    AHEAD_MAX_BEARING_DEG,
    CROSSING_MAX_ANGLE_DEG,
    HEADING_RADIAL_SPEED,
    LANE_HALF_WIDTH,
    SPEED_ABOUT_MIN_TOL,
    SPEED_ABOUT_REL_TOL,
    Atom,
    DepthAbout,
    DepthBetween,
    DepthBeyond,
    DepthWithin,
    Extreme,
    Heading,
    HeadingIs,
    MotionState,
    OnSide,
    Side,
    SpeedAbout,
    SpeedAbove,
    SpeedBelow,
    SpeedUnit,
)
from scenes.prompts.describe import describe, describe_predicate
from scenes.prompts.features import DEFAULT_REGION, ActorFeatures, ReferableRegion
from scenes.prompts.generate import PromptConfig, generate_prompts
from scenes.prompts.numbers import spell_number
from scenes.prompts.phrasing import HELDOUT_VARIANTS, PHRASINGS, TRAIN_VARIANTS
from scenes.prompts.predicate import Predicate, Resolution, analyse, resolve
from scenes.prompts.render import Prompt, render, render_with_variants
from scenes.prompts.tags import TAGS, flip_left_right, infer_tags

__all__ = [
    "ABOUT_DEPTH_TOL",
    "AHEAD_MAX_BEARING_DEG",
    "CROSSING_MAX_ANGLE_DEG",
    "DEFAULT_REGION",
    "HEADING_RADIAL_SPEED",
    "HELDOUT_VARIANTS",
    "LANE_HALF_WIDTH",
    "PHRASINGS",
    "SPEED_ABOUT_MIN_TOL",
    "SPEED_ABOUT_REL_TOL",
    "TAGS",
    "TRAIN_VARIANTS",
    "ActorFeatures",
    "Atom",
    "DepthAbout",
    "DepthBetween",
    "DepthBeyond",
    "DepthWithin",
    "Extreme",
    "Heading",
    "HeadingIs",
    "MotionState",
    "OnSide",
    "Predicate",
    "Prompt",
    "PromptConfig",
    "ReferableRegion",
    "Resolution",
    "Side",
    "SpeedAbout",
    "SpeedAbove",
    "SpeedBelow",
    "SpeedUnit",
    "analyse",
    "describe",
    "describe_predicate",
    "flip_left_right",
    "generate_prompts",
    "infer_tags",
    "render",
    "render_with_variants",
    "resolve",
    "spell_number",
]
