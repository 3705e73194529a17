"""FourierLinear: an equivariant map between regular fields applied in the irrep basis.

It must be a drop-in for ``EquivariantLinear`` (escnn's ``Linear``) between the
same field types: exactly equivariant, the same function class and parameter
count, a matching dense expansion, working gradients and float64.
"""

import math

import numpy as np
import pytest
import torch
from escnn import nn as enn

from agents.nn.escnn_groups import make_group
from agents.nn.fourier import FourierLinear, _FourierMap

GROUPS = ["D4", "D8", "D16", "C8", "octahedral", "icosahedral"]


@pytest.fixture(autouse=True)
def _single_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def field_types(name, c_in, c_out):
    group = make_group(name)
    return (group.gspace.type(*[group.regular] * c_in), group.gspace.type(*[group.regular] * c_out))


def rep_matrices(field_type, dtype=torch.float64):
    """The representation of every group element: [|G|, size, size]."""
    elements = list(field_type.fibergroup.elements)
    return torch.tensor(np.stack([field_type.representation(e) for e in elements]), dtype=dtype)


def layer(name, c_in=3, c_out=2, seed=0, bias=True):
    torch.manual_seed(seed)
    return FourierLinear(*field_types(name, c_in, c_out), bias=bias)


def equivariance_error(lay, x):
    """max_g |f(rho_in(g) x) - rho_out(g) f(x)| / max |f(x)|."""
    rho_in, rho_out = rep_matrices(lay.in_type, x.dtype), rep_matrices(lay.out_type, x.dtype)
    with torch.no_grad():
        fx = lay(x)
        moved = lay(torch.einsum("gij,bj->gbi", rho_in, x))  # every element at once: [|G|, b, size]
        expected = torch.einsum("gij,bj->gbi", rho_out, fx)
    return ((moved - expected).abs().max() / fx.abs().max()).item()


@pytest.mark.parametrize("name", GROUPS)
def test_equivariant_for_every_element_float32(name):
    lay = layer(name)
    x = torch.randn(6, lay.in_type.size)
    assert equivariance_error(lay, x) < 1e-5


@pytest.mark.parametrize("name", GROUPS)
def test_double_precision_is_exact(name):
    lay = layer(name).double()
    assert lay.weights.dtype == lay.fourier_in.dtype == lay.fourier_out_t.dtype == torch.float64
    # Rebuilt from float64 masters, not float32 values widened: orthogonal to float64 precision.
    eye = torch.eye(lay.order, dtype=torch.float64)
    assert torch.allclose(lay.fourier_out_t.T @ lay.fourier_out_t, eye, atol=1e-13)
    x = torch.randn(4, lay.in_type.size, dtype=torch.float64)
    assert equivariance_error(lay, x) < 1e-12
    back = lay.float()
    assert back.fourier_in.dtype == torch.float32 and back(x.float()).dtype == torch.float32


@pytest.mark.parametrize("name", GROUPS)
def test_expand_and_export_are_the_layers_function(name):
    lay = layer(name).double()
    x = torch.randn(2, 3, lay.in_type.size, dtype=torch.float64)  # any leading dimensions
    weight, bias = lay.expand()
    assert weight.shape == (lay.out_type.size, lay.in_type.size) and bias.shape == (lay.out_type.size,)
    with torch.no_grad():
        out = lay(x)
        assert torch.allclose(out, x @ weight.T + bias, atol=1e-12)
        assert torch.allclose(lay.export()(x), out, atol=1e-12)
        assert torch.allclose(lay(x[0, 0]), out[0, 0], atol=1e-12)  # no batch dimension
    # The bias is escnn's: one number per output field, on its constant (trivial) component.
    assert torch.allclose(bias.view(lay.c_out, lay.order),
                          lay.bias[:, None].expand(-1, lay.order) / math.sqrt(lay.order), atol=1e-12)
    no_bias = layer(name, bias=False)
    assert no_bias.bias is None and no_bias.expand()[1] is None and no_bias.export().bias is None


@pytest.mark.parametrize("name", GROUPS)
def test_parameter_count_equals_escnn_linear(name):
    in_type, out_type = field_types(name, 3, 2)
    ours = sum(p.numel() for p in FourierLinear(in_type, out_type).parameters())
    theirs = sum(p.numel() for p in enn.Linear(in_type, out_type).parameters())
    assert ours == theirs == 3 * 2 * make_group(name).order + 2


@pytest.mark.parametrize("c_in, c_out", [(2, 1), (1, 2)])
@pytest.mark.parametrize("name", GROUPS)
def test_same_function_class_as_escnn(name, c_in, c_out):
    """Every expanded matrix commutes with the group, and random parameters span a space
    of escnn's basis dimension: with escnn's basis complete, the two classes are equal."""
    in_type, out_type = field_types(name, c_in, c_out)
    lay = FourierLinear(in_type, out_type, bias=False).double()
    n = lay.weights.numel()
    gen = torch.Generator().manual_seed(1)
    matrices = []
    with torch.no_grad():
        for _ in range(n + 4):
            lay.weights.copy_(torch.randn(n, generator=gen, dtype=torch.float64))
            matrices.append(lay.expand()[0])
    matrices = torch.stack(matrices)  # [n + 4, out, in]
    rho_in, rho_out = rep_matrices(in_type), rep_matrices(out_type)
    commutator = (torch.einsum("kij,gjl->kgil", matrices, rho_in)
                  - torch.einsum("gij,kjl->kgil", rho_out, matrices))
    assert commutator.abs().max() < 1e-12
    escnn_linear = enn.Linear(in_type, out_type, bias=False)
    dimension = escnn_linear.basisexpansion.dimension()
    flat = matrices.flatten(1)
    assert torch.linalg.matrix_rank(flat).item() == dimension == n
    # And escnn's own random map lies in the span (to its float32 precision).
    with torch.no_grad():
        theirs = escnn_linear.expand_parameters()[0].double().flatten()
    coefficients = torch.linalg.lstsq(flat.T, theirs[:, None]).solution
    assert (flat.T @ coefficients).squeeze(1).sub(theirs).abs().max() < 1e-6 * theirs.abs().max()


@pytest.mark.parametrize("name", GROUPS)
def test_gradients_match_the_dense_expansion(name):
    lay = layer(name).double()
    x = torch.randn(5, lay.in_type.size, dtype=torch.float64, requires_grad=True)
    target = torch.randn(5, lay.out_type.size, dtype=torch.float64)
    (lay(x) - target).square().sum().backward()
    fast = (x.grad.clone(), lay.weights.grad.clone(), lay.bias.grad.clone())
    assert all(torch.isfinite(g).all() and g.abs().max() > 0 for g in fast)
    x.grad = None
    lay.zero_grad()
    weight, bias = lay.expand()  # differentiable in the parameters
    (x @ weight.T + bias - target).square().sum().backward()
    for a, b in zip(fast, (x.grad, lay.weights.grad, lay.bias.grad)):
        assert torch.allclose(a, b, atol=1e-10)


@pytest.mark.parametrize("name", ["D4", "C8", "octahedral"])
def test_backward_passes_gradcheck(name):
    lay = layer(name, c_in=2, c_out=2).double()
    x = torch.randn(2, lay.in_type.size, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x, w, b: _FourierMap.apply(x, w, b, lay),
                                    (x, lay.weights, lay.bias))
    # Only the input needs a gradient (a frozen layer) and only the parameters (the first layer).
    frozen = layer(name, c_in=2, c_out=2).requires_grad_(False)
    y = torch.randn(3, frozen.in_type.size, requires_grad=True)
    frozen(y).sum().backward()
    assert y.grad is not None and frozen.weights.grad is None
    first = layer(name, c_in=2, c_out=2)
    first(torch.randn(3, first.in_type.size)).sum().backward()
    assert first.weights.grad is not None and first.bias.grad is not None


@pytest.mark.parametrize("name", ["D8", "C8", "icosahedral"])
def test_initial_statistics_match_escnn(name):
    """Expanded entries of variance 1/fan_in (escnn's generalised He init), spread over
    the irreps as escnn's are (energy d_psi m_psi / c_in per field pair), and biases as
    ``make_linear``'s: uniform in +-1/sqrt(fan_in)."""
    c = 12
    lay = layer(name, c_in=c, c_out=c)
    order = lay.order
    fan_in = c * order
    with torch.no_grad():
        weight, _ = lay.expand()
    assert weight.double().square().mean().item() * fan_in == pytest.approx(1.0, rel=0.15)
    with torch.no_grad():
        escnn_weight, _ = enn.Linear(lay.in_type, lay.out_type).expand_parameters()
    assert escnn_weight.double().square().mean().item() * fan_in == pytest.approx(1.0, rel=0.15)
    assert lay.bias.abs().max() <= 1 / math.sqrt(fan_in)
    # Per irrep type: the energy of its Fourier block, per (output, input) field pair.
    blocks = weight.double().view(c, order, c, order)
    q = torch.tensor(make_group(name).regular.change_of_basis)
    fourier = torch.einsum("ga,ogih,hb->oaib", q, blocks, q)
    position = 0
    columns = {}
    for irrep_id in make_group(name).regular.irreps:
        size = make_group(name).escnn.irrep(*irrep_id).size
        columns.setdefault(irrep_id, []).extend(range(position, position + size))
        position += size
    for irrep_id, cols in columns.items():
        size = make_group(name).escnn.irrep(*irrep_id).size
        energy = fourier[:, cols][:, :, :, cols].square().sum().item() / c ** 2
        assert energy == pytest.approx(len(cols) / c, rel=0.3), irrep_id  # d m / c_in


def test_state_dict_holds_only_parameters_and_round_trips():
    lay = layer("octahedral")
    assert set(lay.state_dict()) == {"weights", "bias"}
    other = layer("octahedral", seed=1)
    other.load_state_dict(lay.state_dict())
    x = torch.randn(3, lay.in_type.size)
    with torch.no_grad():
        assert torch.equal(other(x), lay(x))


def test_moves_to_devices():
    lay = layer("D8").to(torch.device("cpu"))
    assert lay.fourier_in.device.type == "cpu"
    if torch.cuda.is_available():
        cuda = layer("D8").cuda()
        x = torch.randn(4, cuda.in_type.size)
        with torch.no_grad():
            assert torch.allclose(cuda(x.cuda()).cpu(), layer("D8")(x), atol=1e-5)


def test_rejects_fields_that_are_not_regular():
    group = make_group("D4")
    regular = group.gspace.type(group.regular)
    with pytest.raises(ValueError, match="regular fields"):
        FourierLinear(group.gspace.type(group.trivial, group.regular), regular)
    other = make_group("C8")
    with pytest.raises(ValueError, match="share their group"):
        FourierLinear(regular, other.gspace.type(other.regular))


@pytest.mark.parametrize("name", ["D8", "icosahedral"])
def test_split_layer_from_latent_and_action_is_escnns_layer(name):
    """Input layers read (regular latent, action): a FourierLinear on the latent plus an
    EquivariantLinear on the action. Same parameter count as escnn's single layer, its
    forward equals its dense expansion, it is exactly equivariant, and its expanded
    entries have escnn's initial scale (variance ~ 1/fan_in of the whole input)."""
    from agents.nn.layers import EquivariantLinear, SplitLinear, make_linear

    group = make_group(name)
    latent = group.gspace.type(*[group.regular] * 3)
    action = group.gspace.type(group.standard, group.standard)
    out = group.gspace.type(*[group.regular] * 4)
    torch.manual_seed(0)
    split = make_linear(latent + action, out, kind="fourier").double()
    dense = make_linear(latent + action, out, kind="dense").double()
    assert isinstance(split, SplitLinear) and isinstance(dense, EquivariantLinear)
    assert sum(p.numel() for p in split.parameters()) == sum(p.numel() for p in dense.parameters())
    x = torch.randn(7, split.in_type.size, dtype=torch.float64)
    weight, bias = split.expand()
    torch.testing.assert_close(split(x), x @ weight.T + bias)
    reps_in, reps_out = rep_matrices(split.in_type), rep_matrices(split.out_type)
    for g_in, g_out in zip(reps_in[:12], reps_out[:12]):
        torch.testing.assert_close(split(x @ g_in.T), split(x) @ g_out.T)
    dense_weight, _ = dense.expand()
    ratio = (weight.var() / dense_weight.var()).item()
    assert 0.6 < ratio < 1.6, ratio
