"""The vectorised ELU against ATen's: values, gradients, both autograd paths, extremes."""

import pytest
import torch
import torch.nn.functional as F

from agents.nn.activations import ELU, activation

EXTREMES = torch.tensor([-1e4, -104.0, -88.0, -20.0, -1.0, -1e-6, -1e-30, 0.0, 1e-30, 1e-6,
                         1.0, 20.0, 1e4])


def _inputs(dtype: torch.dtype) -> torch.Tensor:
    torch.manual_seed(0)
    return torch.cat([torch.randn(4096, dtype=dtype) * 3, EXTREMES.to(dtype)])


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_values_match_aten_elu(dtype: torch.dtype) -> None:
    x = _inputs(dtype)
    y = ELU()(x)
    positive = x > 0
    assert torch.equal(y[positive], x[positive])  # the identity side is exact
    ulp = torch.finfo(dtype).eps
    assert (y - F.elu(x)).abs().max() <= ulp
    assert y.min() >= -1


def test_gradients_match_aten_elu() -> None:
    x = _inputs(torch.float32).requires_grad_()
    grad_out = torch.randn_like(x)
    (ours,) = torch.autograd.grad(ELU()(x), x, grad_out)
    (aten,) = torch.autograd.grad(F.elu(x), x, grad_out)
    torch.testing.assert_close(ours, aten, rtol=1e-6, atol=1e-6)


def test_gradcheck_in_double() -> None:
    x = (torch.randn(64, dtype=torch.float64) * 2).requires_grad_()
    x = x.detach().where(x.detach().abs() > 1e-3, torch.tensor(0.5, dtype=torch.float64))
    assert torch.autograd.gradcheck(ELU(), (x.requires_grad_(),))


def test_no_grad_path_equals_autograd_path() -> None:
    x = _inputs(torch.float32)
    with torch.no_grad():
        plain = ELU()(x.clone().requires_grad_())
    tracked = ELU()(x.clone().requires_grad_())
    assert tracked.requires_grad and not plain.requires_grad
    assert torch.equal(plain, tracked.detach())


def test_input_is_not_modified() -> None:
    x = _inputs(torch.float32)
    before = x.clone()
    ELU()(x)
    assert torch.equal(x, before)


def test_unknown_activation_names_the_valid_ones() -> None:
    with pytest.raises(ValueError, match="unknown activation 'swish'; valid: mish, elu, relu, silu"):
        activation("swish")
