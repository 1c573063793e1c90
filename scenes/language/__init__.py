"""The language: generated prompts with exact referents (``prompts``) and the language suite's hand-
written queries (``query``) and their resolution (``resolve``).

It imports ``scenes.geometry`` and ``scenes.utils`` only.
"""
