"""The operating threshold: chosen by mean set F1 on a split, stored in the checkpoint."""

from pathlib import Path

import numpy as np
import pytest

from model.evaluation.grounding import PromptBoxes
from model.evaluation.predict import operating_threshold
from model.training.calibrate import choose_threshold, main
from scenes.talk2radar.layout import LABEL, LIDAR_FOLDER, sample_dir

CAR = np.array([[15.0, 0.0, -0.9, 4.0, 1.8, 1.5, 0.0]])
OTHER = np.array([[25.0, 5.0, -0.9, 4.0, 1.8, 1.5, 0.0]])


def _answer(scores: tuple[float, float]) -> tuple[PromptBoxes, PromptBoxes]:
    """The referent scored ``scores[0]``, a wrong car ``scores[1]``."""
    predicted = PromptBoxes.make(np.r_[CAR, OTHER], ["Car", "Car"], np.array(scores))
    return predicted, PromptBoxes.make(CAR, ["Car"])


def test_choose_threshold_keeps_the_referents_and_drops_the_rest():
    # Referents at 0.8 and 0.7, wrong boxes at 0.5 and 0.3: any threshold in (0.5, 0.7] is exact.
    cal = choose_threshold([_answer((0.8, 0.5)), _answer((0.7, 0.3))], (0.2, 0.4, 0.6, 0.75, 0.9))
    assert cal.threshold == 0.6 and cal.set_f1 == pytest.approx(100.0)
    assert cal.exact_set == pytest.approx(100.0) and cal.prompts == 2
    curve = {t: (f1, exact) for t, f1, exact in cal.curve}
    assert curve[0.2] == pytest.approx((100 * 2 / 3, 0.0))  # both boxes kept: F1 2/3
    assert curve[0.75][1] == pytest.approx(50.0)  # the 0.7 referent lost
    with pytest.raises(ValueError, match="no prompts"):
        choose_threshold([])


def test_choose_threshold_takes_the_highest_of_a_plateau():
    # 200 prompts: the referent always at 0.9; a wrong box at 0.3 in one prompt (a 0.17-point F1
    # cost at thresholds <= 0.3), the referent of another at 0.5 (lost above 0.5: 0.5 points).
    answers = [_answer((0.9, 0.1)) for _ in range(198)]
    answers += [_answer((0.9, 0.3)), _answer((0.5, 0.1))]
    cal = choose_threshold(answers, (0.2, 0.4, 0.6, 0.8))
    curve = {t: f1 for t, f1, _ in cal.curve}
    assert curve[0.4] == pytest.approx(100.0) and curve[0.6] == pytest.approx(99.5)
    assert curve[0.2] < curve[0.4]
    assert cal.threshold == 0.8  # 0.6 and 0.8 lose 0.5 points: within the plateau, the highest
    lost = answers + [_answer((0.5, 0.1))] * 2  # now 1.5 points lost above 0.5: outside it
    assert choose_threshold(lost, (0.2, 0.4, 0.6, 0.8)).threshold == 0.4


def test_command_writes_the_threshold_into_the_checkpoint(tmp_path: Path, write_tiny_root):
    from model import build_model
    from model.checkpoint import load_checkpoint, save_checkpoint

    root = write_tiny_root(tmp_path / "root", frames=2)
    path = save_checkpoint(tmp_path / "m.pt", build_model("small", text_encoder="gru"), step=3)
    args = ["--data", str(root), "--checkpoint", str(path), "--split", "test"]
    assert main([*args, "--min-prompts", "2"]) == 0
    meta = load_checkpoint(path).checkpoint_metadata
    assert meta.step == 3  # the rest of the metadata is kept
    source = meta.operating_threshold_source
    assert source["split"] == "test" and source["prompts"] == 2
    assert operating_threshold(load_checkpoint(path)) == meta.operating_threshold
    assert main(["--data", str(root / "nowhere"), "--checkpoint", str(path)]) == 2


def _one_line_error(capsys: pytest.CaptureFixture) -> str:
    """The one error line on stderr (beside the progress bar's), no traceback."""
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_a_split_that_cannot_measure_a_threshold_is_refused(
    tmp_path: Path, write_tiny_root, capsys: pytest.CaptureFixture
):
    """Prompts that refer to nothing (any threshold returning nothing scores set F1 100 there),
    or too few that refer to something: exit 2, one line, the checkpoint byte for byte as it was."""
    from model import build_model
    from model.checkpoint import save_checkpoint
    from model.training.calibrate import MIN_REFERRED_PROMPTS

    root = write_tiny_root(tmp_path / "root", frames=2)
    path = save_checkpoint(tmp_path / "m.pt", build_model("small", text_encoder="gru"), step=3)
    before = path.read_bytes()
    args = ["--data", str(root), "--checkpoint", str(path), "--split", "test"]
    assert main(args) == 2  # 2 prompts with a referent, fewer than the minimum
    line = _one_line_error(capsys)
    assert "2 of the 2 prompts of split 'test' have a referent" in line
    assert f"at least {MIN_REFERRED_PROMPTS}" in line and "test.txt" in line
    for label in sample_dir(root / LIDAR_FOLDER, LABEL).glob("*.txt"):
        label.write_text("")  # every prompt refers to nothing
    assert main([*args, "--min-prompts", "1"]) == 2
    assert "0 of the 2 prompts" in _one_line_error(capsys)
    assert main([*args, "--min-prompts", "0"]) == 2  # never below one referred prompt
    assert "0 of the 2 prompts" in _one_line_error(capsys)
    assert path.read_bytes() == before
