"""``python -m model.results_table``: the command of :mod:`model.evaluation.results_table`."""

import sys

from model.evaluation.results_table import main

if __name__ == "__main__":
    sys.exit(main())
