"""The simulation: the synthetic world, its sensors and weather, a frame and a root generated from
it (``python -m scenes.synth``), and what View-of-Delft labels of it.

It imports the rooms below it (``talk2radar``, ``language``, ``geometry``, ``utils``).
"""
