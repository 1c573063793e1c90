"""Throughput of ``python -m model.evaluate`` on a 300-prompt root: ``python -m bench.eval_throughput``, the stable command line.

The module lives in :mod:`bench.perf.eval_throughput`; this entry only calls its ``main``, so that the
command named in the issues and the docs keeps working where the module moved.
"""

from __future__ import annotations

from bench.perf.eval_throughput import main

if __name__ == "__main__":
    raise SystemExit(main())
