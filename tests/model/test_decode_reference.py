"""Decoding, candidate description and ``ground`` give what the reference code gave: the same
candidates (boxes, labels, scores, every feature), the same answers and the same decoded boxes of
an untrained head with hundreds of peaks, within :data:`TOLERANCE` (:data:`DECODE_TOLERANCE` for
that head's decoding alone). Reference file and its regeneration: :mod:`tests.decode_reference`;
it was made on the code before issue 20's speed-ups and regenerated once for the network's
inference forms, whose rounding change docs/RESULTS.md states."""

from __future__ import annotations

import numpy as np
import pytest

from tests.decode_reference import REFERENCE, reference_outputs

TOLERANCE = 1e-4
"""Largest difference allowed on a trained network's float outputs (features, m, rad,
probabilities). The reference is made on one machine and checked on others: float32 kernels differ
between CPUs (vector width, fused multiply-add) by a few units in the last place, and the network
carries that to at most 4.1e-5 on its candidate features and 1.8e-5 on a candidate box
(measured on an Intel Xeon without AVX-512 against the reference's machine); every discrete
output is compared exactly."""

DECODE_TOLERANCE = 1e-6
"""The same for the untrained head's decoded boxes and scores (``untrained/``): decoding alone,
whose inputs are nearly the same everywhere (8.8e-8 apart on that machine)."""


@pytest.fixture(scope="module")
def reference() -> dict[str, np.ndarray]:
    with np.load(REFERENCE) as data:
        return {k: data[k] for k in data.files}


@pytest.fixture(scope="module")
def current() -> dict[str, np.ndarray]:
    return reference_outputs()


def test_reference_inputs_are_todays_generator(reference) -> None:
    from scenes.synth.frame import GENERATOR_VERSION

    assert int(reference["generator_version"]) == GENERATOR_VERSION, (
        "the generator changed since the reference was made: its frames are other inputs; "
        "regenerate with `python -m tests.decode_reference` on the code before the change"
    )


def test_same_outputs_as_the_reference(reference, current) -> None:
    expected = {k: v for k, v in reference.items() if "/" in k}
    assert sorted(current) == sorted(expected)
    for key, want in expected.items():
        got = current[key]
        assert got.shape == want.shape, f"{key}: shape {got.shape}, reference {want.shape}"
        if want.dtype.kind in "iUb":
            np.testing.assert_array_equal(got, want, err_msg=key)
        else:
            atol = DECODE_TOLERANCE if key.startswith("untrained/") else TOLERANCE
            np.testing.assert_allclose(got, want, rtol=0, atol=atol, err_msg=key)


def test_the_untrained_head_exercises_nms(reference) -> None:
    # The case is only a test of NMS if many boxes survive the threshold: all 50 slots are full.
    assert len(reference["untrained/cand/boxes"]) == 50
    assert len(reference["untrained/head/boxes"]) == 50
