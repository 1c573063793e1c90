"""Benchmarks and studies (scripts, not tests), by kind: :mod:`bench.perf` (timings: latency,
FLOP floor, fusion and graph cost, model size, training and evaluation throughput, scene
generation speed, server memory), :mod:`bench.studies` (accuracy studies and suites: language
suite, sensor shift, people's commands, Talk2Car recall, fit and carry accuracy, ...) and
:mod:`bench.devkit` (cross-checks with the official devkits). ``python -m bench.run_all``
(``make bench``) runs the benchmarks and regenerates ``docs/PERFORMANCE.md``; each writes
``bench/results/<name>.json``. The helpers every kind shares stay here: :mod:`bench.common` (the
command line, re-exporting :mod:`bench.report`, :mod:`bench.measure` and :mod:`bench.workloads`).
The modules left at this level under a moved module's old name (``eval_throughput``, ``floor``,
``language_suite``, ``sensor_shift``, ``people_commands``, ``talk2car_recall``) are its stable
command line only. The suite's data lives in ``bench/data/``.
"""
