"""Performance benchmarks (timings and sizes): per-prompt latency (``latency`` with
``latency_measure`` and ``latency_report``), time against the FLOP floor (``floor`` with
``floor_measure``, on real-size View-of-Delft frames from ``vod_frames``), the parts of a model
timed one by one (``model_parts``), fusion and graph cost, model size, training and evaluation
throughput, scene generation speed (``bench_synth``) and server memory over many browser visits
(``soak``). Each writes ``bench/results/<name>.json``; :mod:`bench.run_all` renders them.
"""
