"""``python -m scenes.synth``: generate a synthetic root (:func:`scenes.synth.generate.main`)."""

import sys

from scenes.synth.generate import main

if __name__ == "__main__":
    sys.exit(main())
