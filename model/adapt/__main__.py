"""``python -m model.adapt``: 0 when done (or stopped by ``--stop-after-round``), 2 on bad input
(one line, ``error: ...``) or an ``--out`` another run is writing (its lock,
:mod:`scenes.utils.run_lock`: the line names that run), 130 / 143 on SIGINT / SIGTERM (the state
saved: run it again)."""

from __future__ import annotations

import sys

from model.adapt.config import AdaptError, parse_args
from model.adapt.run import adapt, report_table
from model.adapt.state import LAST_FILE, REPORT_FILE
from model.training.stop_signal import TrainingInterrupted
from scenes.utils.cli import error_line
from scenes.utils.run_lock import RunLockError, run_lock


def main(argv: list[str] | None = None) -> int:
    """The command (module docstring)."""
    try:
        cfg = parse_args(argv)
        with run_lock(cfg.out):  # one writer per run folder
            report = adapt(cfg)
    except TrainingInterrupted as exc:
        print(exc.message(), file=sys.stderr)
        return exc.exit_code
    except (AdaptError, RunLockError, OSError) as exc:
        print(f"error: {error_line(exc)}", file=sys.stderr)
        return 2
    print(report_table(report))
    done = sum(1 for e in report if e["steps"] == cfg.steps_per_round)
    print(f"{done} of {cfg.rounds} rounds done; {cfg.out}/{LAST_FILE}, {cfg.out}/{REPORT_FILE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
