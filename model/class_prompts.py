"""``python -m model.class_prompts``: the command of :mod:`model.evaluation.class_prompts`."""

import sys

from model.evaluation.class_prompts import main

if __name__ == "__main__":
    sys.exit(main())
