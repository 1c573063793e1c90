"""The detector's ceiling on a split's Talk2Car commands: ``python -m bench.talk2car_recall``, the stable command line.

The module lives in :mod:`bench.studies.talk2car_recall`; this entry only calls its ``main``, so that the
command named in the issues and the docs keeps working where the module moved.
"""

from __future__ import annotations

from bench.studies.talk2car_recall import main

if __name__ == "__main__":
    raise SystemExit(main())
