"""Benchmarks (scripts, not tests): latency, fusion cost, graph cost, model size, training
throughput and scene generation speed. ``python -m bench.run_all`` (``make bench``) runs them all
and regenerates ``docs/PERFORMANCE.md``; each ``python -m bench.<name>`` runs one and writes
``bench/results/<name>.json``. Shared output and measurement helpers live in :mod:`bench.common`.
"""
