"""People's own Talk2Car commands on synthetic frames: ``python -m bench.people_commands``, the stable command line.

The module lives in :mod:`bench.studies.people_commands`; this entry only calls its ``main``, so that the
command named in the issues and the docs keeps working where the module moved.
"""

from __future__ import annotations

from bench.studies.people_commands import main

if __name__ == "__main__":
    raise SystemExit(main())
