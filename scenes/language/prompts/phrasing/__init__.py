"""The generator's wording: its slots, their variants and the train / held-out split.

A *slot* is one choice a sentence makes: the command or question frame, the class noun, a
determiner, each attribute's phrase, a unit, the number style, the casing, ... Its *variants* are
the ways to say it. The package holds one concept a module:

- :mod:`~scenes.language.prompts.phrasing.slots`: the slot vocabularies (:class:`Slot`,
  ``SLOTS``: the base language's, with the ``nuscenes`` class set's road users,
  ``ROAD_USER_SLOTS``).
- :mod:`~scenes.language.prompts.phrasing.split`: the train / held-out split of the variants
  (``PromptConfig.phrasing``: ``PHRASINGS``, ``split_variants``, ``TRAIN_VARIANTS``,
  ``HELDOUT_VARIANTS``, ``variants``), which the commands and people's tables apply too.
- :mod:`~scenes.language.prompts.phrasing.slot_choice`: which slot says what (an atom's phrase,
  adjective or superlative slot; a class's slot suffix, ``CLASS_KEYS``) and which noun variants
  say more than their class in a class set (``WIDER_THAN_CLASS``, ``too_wide``).
- :mod:`~scenes.language.prompts.phrasing.extra`: the extended language's wording of the base
  slots (``EXTRA`` variants, ``DROPPED`` ones).
- :mod:`~scenes.language.prompts.phrasing.family_slots`: the compositional families' templates
  (``FAMILY_SLOTS``: negation, exclusion, ordinals, relations, counting, ...).

Every variant is written so that it stays literally true of the referents and
:func:`scenes.language.prompts.tags.infer_tags` finds exactly its atom's tag in it.
"""
