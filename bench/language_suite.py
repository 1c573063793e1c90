"""The language suite: a checkpoint on sentences people type, per family: ``python -m bench.language_suite``, the stable command line.

The module lives in :mod:`bench.studies.language_suite`; this entry only calls its ``main``, so that the
command named in the issues and the docs keeps working where the module moved.
"""

from __future__ import annotations

from bench.studies.language_suite import main

if __name__ == "__main__":
    raise SystemExit(main())
