"""Where the command-line helper was: it lives in :mod:`scenes.utils.cli` (the bottom package, so that
every package may use it); this name re-exports it for code written against the old place."""

from scenes.utils.cli import add_options, choices_of, flag_name, from_args, option, resumable_fields

__all__ = ["add_options", "choices_of", "flag_name", "from_args", "option", "resumable_fields"]
