"""``python -m model.calibrate``: the command of :mod:`model.training.calibrate`."""

import sys

from model.training.calibrate import main

if __name__ == "__main__":
    sys.exit(main())
