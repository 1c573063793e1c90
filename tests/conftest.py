"""Session-wide test settings.

Torch runs with one intra-op thread in the test process: on a 2-core machine the suite's own
servers, browser and subprocesses share the cores, and torch's OpenMP pool with two threads slows
down many times over when a core is taken (see docs/PERFORMANCE.md's thread table), which turned
the overfit test's two minutes into a timeout on a loaded machine.
"""

import torch

torch.set_num_threads(1)
