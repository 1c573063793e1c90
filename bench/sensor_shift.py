"""Detection on sensors training never saw (issue 38): ``python -m bench.sensor_shift``, the stable command line.

The module lives in :mod:`bench.studies.sensor_shift`; this entry only calls its ``main``, so that the
command named in the issues and the docs keeps working where the module moved.
"""

from __future__ import annotations

from bench.studies.sensor_shift import main

if __name__ == "__main__":
    raise SystemExit(main())
