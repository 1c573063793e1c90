"""``python -m model.train``: the command of :mod:`model.training.loop`."""

import sys

from model.training.loop import main

if __name__ == "__main__":
    sys.exit(main())
