"""DGGF's grouped max-relative pass equals Algorithm 1's roll loop (values and gradients)."""

import pytest
import torch

from model.nets.dggf import dynamic_max_relative, dynamic_max_relative_loop


@pytest.mark.parametrize(
    ("shape", "k"),
    [((2, 8, 16, 24), 4), ((2, 16, 40, 40), 8), ((3, 4, 20, 20), 2), ((1, 3, 9, 12), 3)],
)
def test_grouped_equals_loop(shape, k):
    torch.manual_seed(0)
    x = torch.randn(*shape)
    x[:, :, : shape[2] // 2] *= 0.1  # similar cells, so that edges exist
    xa, xb = x.clone().requires_grad_(), x.clone().requires_grad_()
    a, b = dynamic_max_relative(xa, k), dynamic_max_relative_loop(xb, k)
    assert (b > 0).any() and (b == 0).any()  # some nodes with edges, some without
    torch.testing.assert_close(a, b, rtol=0, atol=0)
    weights = torch.randn_like(a)
    (a * weights).sum().backward()
    (b * weights).sum().backward()
    torch.testing.assert_close(xa.grad, xb.grad, rtol=1e-5, atol=1e-6)


def test_indivisible_axis_falls_back_to_the_loop():
    x = torch.randn(1, 4, 10, 12)
    torch.testing.assert_close(dynamic_max_relative(x, 3), dynamic_max_relative_loop(x, 3))


def test_inference_uses_the_loop_and_agrees():
    x = torch.randn(1, 8, 16, 16)
    with torch.no_grad():
        torch.testing.assert_close(dynamic_max_relative(x, 4), dynamic_max_relative_loop(x, 4))
