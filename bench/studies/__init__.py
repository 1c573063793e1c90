"""Accuracy studies and suites: how well something lands, not how fast. The language suite
(``language_suite`` with ``language_cases``, ``language_score``, ``language_generator``; its data
``bench/data/language_suite.json``), detection on held-out sensors (``sensor_shift``), the
synthetic sensors beside View-of-Delft's (``sensor_stats``), class prompts over labelled boxes
(``labelled_shift``), people's Talk2Car commands (``people_commands`` with ``people_frames``),
the detector's ceiling on Talk2Car commands (``talk2car_recall``) and the annotation tools'
accuracy (``fit_accuracy``, ``carry_accuracy``).
"""
