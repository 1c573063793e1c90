"""Time against the FLOP floor on real-size frames: ``python -m bench.floor``, the stable command line.

The module lives in :mod:`bench.perf.floor`; this entry only calls its ``main``, so that the
command named in the issues and the docs keeps working where the module moved.
"""

from __future__ import annotations

from bench.perf.floor import main

if __name__ == "__main__":
    raise SystemExit(main())
