"""Talk2Radar-style referring prompts whose referents are known exactly.

A prompt is generated from a :class:`Predicate`, a small conjunction over the actors of a frame:
an optional class (``Car``, ``Pedestrian``, ``Cyclist``, or any class of a preset of
:mod:`scenes.geometry.classes` with ``PromptConfig.classes``; ``None`` = any class, "objects"), at most
one atom per family (position :class:`OnSide`, motion :class:`MotionState`, heading
:class:`HeadingIs`, speed :class:`SpeedAbout` / :class:`SpeedAbove` / :class:`SpeedBelow`, depth
:class:`DepthAbout` / :class:`DepthBetween` / :class:`DepthWithin` / :class:`DepthBeyond`) and an
optional superlative (:class:`Extreme`). :func:`resolve` evaluates it over all referable actors
and the sentence is rendered afterwards from the size of the resolved set, so a stated count
always equals the number of referents.

Modules, in import order (each imports only those above it):

* :mod:`~scenes.language.prompts.tags` -- keyword type tags (:func:`infer_tags`), :func:`flip_left_right`
  and :func:`is_count_question`, for any text, generated or typed.
* :mod:`~scenes.language.prompts.numbers` -- numbers in digits or words.
* :mod:`~scenes.language.prompts.noise` -- :func:`perturb`, meaning-keeping text noise for training.
* :mod:`~scenes.language.prompts.features` -- :class:`ActorFeatures` and the :class:`ReferableRegion`.
* :mod:`~scenes.language.prompts.atoms` -- the atoms, superlatives and their exact semantics.
* :mod:`~scenes.language.prompts.predicate` -- :class:`Predicate`, :func:`analyse`, :func:`resolve`,
  ambiguity and crispness.
* :mod:`~scenes.language.prompts.phrasing` -- the wording: the slot vocabularies (``slots``), their
  train / held-out split (``split``), which slot says what (``slot_choice``), the extended
  language's extra variants (``extra``) and the compositional families' templates
  (``family_slots``).
* :mod:`~scenes.language.prompts.sampling` -- :class:`PromptConfig`, the families and languages, and
  predicates sampled from an anchor actor.
* :mod:`~scenes.language.prompts.render` -- :class:`Prompt` and :func:`render` (predicate -> sentence).
* :mod:`~scenes.language.prompts.families` -- the compositional families' exact semantics: :class:`Not`,
  :class:`Exclusion`, :class:`Ordinal`, :class:`Related`, :class:`Count`, unsatisfiable.
* :mod:`~scenes.language.prompts.nouns` -- out-of-class things (no referent) and nonsense text.
* :mod:`~scenes.language.prompts.compose_render` -- sentences of the compositional families.
* :mod:`~scenes.language.prompts.commands` -- driving commands around a single-referent description
  (:func:`as_command`, ``PromptConfig.command_share``).
* :mod:`~scenes.language.prompts.extended` -- the extended language's generator (every family).
* :mod:`~scenes.language.prompts.generate` -- :func:`generate_prompts` (base, or extended by
  ``PromptConfig.language``).
* :mod:`~scenes.language.prompts.describe` -- :func:`describe` (a sentence for a given set of actors).

``PromptConfig(language="extended")`` adds the compositional families (negation of any atom,
exclusion, ordinals, relations to another object, counting questions) and prompts whose referent
set is empty (things outside the classes, nonsense, predicates nothing satisfies), in a wider
wording; ``base`` (the default) is the generator as it was, prompt for prompt.

Type tags (``class``, ``depth``, ``velocity``, ``motion``, ``position``, the TPCNet paper's table
III types) follow the predicate, and every phrasing is written so that :func:`infer_tags` (which
also serves real Talk2Radar prompts) gives the same tags from the text.
"""

from scenes.language.prompts.atoms import (
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
from scenes.language.prompts.commands import as_command
from scenes.language.prompts.describe import describe, describe_predicate
from scenes.language.prompts.families import (
    Count,
    Exclusion,
    Not,
    Ordinal,
    Related,
    Relation,
)
from scenes.language.prompts.features import DEFAULT_REGION, ActorFeatures, ReferableRegion
from scenes.language.prompts.generate import PromptConfig, generate_prompts
from scenes.language.prompts.noise import perturb
from scenes.language.prompts.numbers import spell_number
from scenes.language.prompts.phrasing.split import HELDOUT_VARIANTS, PHRASINGS, TRAIN_VARIANTS
from scenes.language.prompts.predicate import Predicate, Resolution, analyse, resolve
from scenes.language.prompts.render import Prompt, render, render_with_variants
from scenes.language.prompts.sampling import EXTENDED_RATES, FAMILIES, LANGUAGES
from scenes.language.prompts.tags import TAGS, flip_left_right, infer_tags, is_count_question

__all__ = [
    "ABOUT_DEPTH_TOL",
    "AHEAD_MAX_BEARING_DEG",
    "CROSSING_MAX_ANGLE_DEG",
    "DEFAULT_REGION",
    "EXTENDED_RATES",
    "FAMILIES",
    "HEADING_RADIAL_SPEED",
    "HELDOUT_VARIANTS",
    "LANE_HALF_WIDTH",
    "LANGUAGES",
    "PHRASINGS",
    "SPEED_ABOUT_MIN_TOL",
    "SPEED_ABOUT_REL_TOL",
    "TAGS",
    "TRAIN_VARIANTS",
    "ActorFeatures",
    "Atom",
    "Count",
    "DepthAbout",
    "DepthBetween",
    "DepthBeyond",
    "DepthWithin",
    "Exclusion",
    "Extreme",
    "Heading",
    "HeadingIs",
    "MotionState",
    "Not",
    "OnSide",
    "Ordinal",
    "Predicate",
    "Prompt",
    "PromptConfig",
    "ReferableRegion",
    "Related",
    "Relation",
    "Resolution",
    "Side",
    "SpeedAbout",
    "SpeedAbove",
    "SpeedBelow",
    "SpeedUnit",
    "analyse",
    "as_command",
    "describe",
    "describe_predicate",
    "flip_left_right",
    "generate_prompts",
    "infer_tags",
    "is_count_question",
    "perturb",
    "render",
    "render_with_variants",
    "resolve",
    "spell_number",
]
