"""The train / held-out split of the generator's variants (``PromptConfig.phrasing``).

Within a *group* (the slot name before any ``/``, so ``motion.stationary/car`` and
``motion.stationary/cyclist`` split alike and a word is held out for every class at once), the
``more`` texts that are not core anywhere in the group are ranked by CRC-32 of their id
``group:text`` and the first ``max(1, round(k / 3))`` of the ``k`` are held out; ``core`` variants
are always ``train``. The rank of a variant does not depend on the table's order, so adding a
variant moves at most one other. :func:`split_variants` is the one home of the rule: the
commands' and people's tables (:mod:`scenes.language.prompts.commands`,
:mod:`scenes.language.prompts.people`) apply it to their own slots too.
"""

from __future__ import annotations

import zlib

from scenes.language.prompts.phrasing.slots import SLOTS, Slot

PHRASINGS = ("train", "heldout", "all")
"""Values of ``PromptConfig.phrasing``: which variants a stream draws from."""

HELDOUT_SHARE = 1.0 / 3.0
"""Share of each group's ``more`` variants that are held out (at least one)."""


def group_of(slot: str) -> str:
    """The split group of a slot: its name before any ``/``."""
    return slot.split("/", 1)[0]


def variant_id(slot: str, text: str) -> str:
    """The id of a variant, ``group:text`` (equal texts of one group are one variant)."""
    return f"{group_of(slot)}:{text}"


def split_variants(slots: dict[str, Slot]) -> tuple[frozenset[str], frozenset[str]]:
    """Ids of the ``train`` and ``heldout`` variants of ``slots`` by the module docstring's rule
    (per group: the ``more`` texts not core anywhere in the group, ranked by CRC-32 of their id,
    the first ``max(1, round(k / 3))`` held out); the one home of the rule, which
    :mod:`scenes.language.prompts.commands` applies to its own table too."""
    core: dict[str, set[str]] = {}
    more: dict[str, set[str]] = {}
    for name, slot in slots.items():
        g = group_of(name)
        core.setdefault(g, set()).update(variant_id(name, t) for t in slot.core)
        more.setdefault(g, set()).update(variant_id(name, t) for t in slot.more)
    train: set[str] = set()
    heldout: set[str] = set()
    for g, ids in core.items():
        rest = sorted(more[g] - ids, key=lambda i: (zlib.crc32(i.encode()), i))
        k = max(1, round(len(rest) * HELDOUT_SHARE)) if rest else 0
        heldout.update(rest[:k])
        train.update(ids, rest[k:])
    return frozenset(train), frozenset(heldout)


TRAIN_VARIANTS, HELDOUT_VARIANTS = split_variants(SLOTS)
"""Ids (``group:text``) of the ``train`` and ``heldout`` variants; disjoint, together all."""


def variants(phrasing: str) -> frozenset[str]:
    """Ids of the variants a ``phrasing`` stream draws from (``heldout`` draws from all, see
    :func:`scenes.language.prompts.render.render`).

    Raises:
        ValueError: ``phrasing`` is not one of :data:`PHRASINGS`.
    """
    if phrasing == "train":
        return TRAIN_VARIANTS
    if phrasing in ("heldout", "all"):
        return TRAIN_VARIANTS | HELDOUT_VARIANTS
    raise ValueError(f"phrasing must be one of {PHRASINGS}, got {phrasing!r}")
