"""agents.compat against the installed dependencies: each adapter still reaches the
private internal it wraps, and that internal still means what the project relies on.

A failure names the dependency, its installed version and what changed: the fix
belongs in ``agents/compat/<dependency>.py`` (gymnasium's: ``geomdp_envs/compat.py``),
nowhere else. Also here: public APIs that replaced a private one, checked to give
bit-identical numbers (``target_lag``).
"""

import contextlib
import copy
import subprocess
import sys
import warnings
from collections import Counter
from importlib.metadata import version

import gymnasium
import numpy as np
import pytest
import torch
from escnn import group as escnn_group
from escnn import gspaces
from escnn import nn as enn
from tensordict import TensorDict
from tensordict.nn import TensorDictParams
from torch import nn
from torchrl.objectives import LossModule, SoftUpdate

from agents.compat.escnn import (
    BASIS_EXPANSION,
    LINEAR_BUFFERS,
    basis_blocks,
    bias_expansion,
    is_basis_expansion_key,
    is_linear_buffer,
    own_basis_expansion,
    use_exact_null_space,
)
from agents.compat.torch import ConversionHook, TorchDispatchMode, child_modules, parameter_table
from agents.compat.torchrl import (
    expect_target_updater,
    prioritized_replay_available,
    priority_state,
    restore_priority_state,
)
from agents.options import OptionError
from agents.tdmpc.agent import TDMPCAgent, TDMPCConfig, rebuilt_with_networks
from agents.tdmpc.replay import (
    ReplayConfig,
    load_replay,
    make_replay_buffer,
    save_replay,
    update_priorities,
)
from geomdp_envs.compat import can_observe, observe, random_state, restore_random_state

# geomdp_envs does not import agents, so gymnasium's adapter is its own
ADAPTERS = {"gymnasium": "geomdp_envs/compat.py"}


def changed(dependency: str, what: str) -> str:
    adapter = ADAPTERS.get(dependency, f"agents/compat/{dependency}.py")
    return f"{dependency} {version(dependency)}: {what} (the adapter to fix: {adapter})"


@contextlib.contextmanager
def internal(dependency: str, what: str):
    """Turn an internal that is gone (AttributeError, KeyError, ...) into a clear failure."""
    try:
        yield
    except (AttributeError, KeyError, TypeError, IndexError) as err:
        pytest.fail(changed(dependency, f"{what} is gone or changed shape ({err!r})"))


# ----------------------------------------------------------------------------- torch


class _EqualByValue(nn.Module):
    """A module that hashes and compares by value, as escnn's basis modules do."""

    def __eq__(self, other):
        return isinstance(other, _EqualByValue)

    def __hash__(self):
        return 0


def test_torch_child_modules():
    parent = nn.Module()
    a, b, c = _EqualByValue(), _EqualByValue(), nn.Linear(1, 1)
    parent.a, parent.b = a, b
    parent.register_module("empty", None)
    parent.c = c
    with internal("torch", "Module._modules"):
        children = child_modules(parent)
    assert [id(m) for m in children] == [id(a), id(b), id(c)], changed(
        "torch", "Module._modules no longer lists the registered children, in order")
    layer = enn.Linear(*_types("D4", ["regular"], ["regular"]))
    assert any(m is layer.basisexpansion for m in child_modules(layer)), changed(
        "torch", "Module._modules does not hold escnn's basis expansion")


def test_torch_parameter_table():
    torch.manual_seed(0)
    lin = nn.Linear(3, 2)
    original = lin.weight
    x = torch.randn(4, 3)
    with internal("torch", "Module._parameters"):
        table = parameter_table(lin)
        assert list(table) == ["weight", "bias"] and table["weight"] is original, changed(
            "torch", "Module._parameters is not the module's name -> Parameter table")
        table["weight"] = original.detach()
    alias = lin.weight
    assert alias is not original and not alias.requires_grad and alias.data_ptr() == original.data_ptr(), \
        changed("torch", "a tensor written into Module._parameters is not what the module reads")
    lin(x).sum().backward()
    assert original.grad is None and lin.bias.grad is not None, changed(
        "torch", "a forward after a write into Module._parameters does not use the written tensor")
    table["weight"] = original
    assert lin.weight is original and [p is original for p in lin.parameters()] == [True, False], \
        changed("torch", "restoring a Parameter through Module._parameters does not restore it")


class _Exact(ConversionHook):
    def __init__(self):
        super().__init__()
        self.master = torch.tensor([0.1, 1 / 3], dtype=torch.float64)
        self.register_buffer("value", self.master.float(), persistent=False)
        self.calls = []

    def converted(self):
        self.calls.append(self.value.dtype)
        self.register_buffer("value", self.master.to(self.value.dtype), persistent=False)


def test_torch_conversion_hook():
    m = _Exact()
    parent = nn.Sequential(m)
    with internal("torch", "Module._apply"):
        parent.double()
    assert m.calls == [torch.float64], changed(
        "torch", "Module.double() no longer goes through Module._apply (or no longer "
                 "converts the buffers before it returns)")
    assert torch.equal(m.value, m.master), "the hook did not rebuild the buffer"
    for convert in (lambda: m.float(), lambda: m.to(torch.float64), lambda: m.cpu(),
                    lambda: m.to("cpu", torch.float32)):
        convert()
    assert m.calls == [torch.float64, torch.float32, torch.float64, torch.float64, torch.float32], \
        changed("torch", ".float/.to/.cpu no longer all go through Module._apply")
    assert "value" not in m.state_dict(), "the rebuilt buffer became persistent"


def test_torch_dispatch_mode_counts_flops():
    """What benchmarks/agent_speed.py does with it: torch's FLOP formulas per aten op."""
    from torch.utils.flop_counter import flop_registry

    class Count(TorchDispatchMode):
        total = 0

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            out = func(*args, **(kwargs or {}))
            formula = flop_registry.get(func.overloadpacket)
            if formula is not None:
                Count.total += formula(*args, out_val=out)
            return out

    a, b = torch.randn(3, 4), torch.randn(4, 5)
    with internal("torch", "torch.utils._python_dispatch.TorchDispatchMode"), Count():
        a @ b
    assert Count.total == 2 * 3 * 4 * 5, changed(
        "torch", "a TorchDispatchMode no longer sees aten.mm with its FLOP formula")


# target_lag's norms: torch.nn.utils.get_total_norm (public) in place of the private
# torch._foreach_norm/_foreach_sub it was computed with. target_lag is logged to
# train.csv every episode, so the two must agree to the bit, not approximately.


@torch.no_grad()
def _old_target_lag(online, target):
    """target_lag as it was computed before (the private foreach ops), the reference."""
    gap = torch.stack(torch._foreach_norm(torch._foreach_sub(online, target))).norm()
    return float(gap / torch.stack(torch._foreach_norm(online)).norm())


@torch.no_grad()
def _new_target_lag(online, target):
    """What TDMPCAgent.target_lag computes now."""
    gap = torch.nn.utils.get_total_norm([o - t for o, t in zip(online, target)], foreach=True)
    return float(gap / torch.nn.utils.get_total_norm(online, foreach=True))


SHAPES = [[(3,)], [(7, 5), (5,), (1,)], [(), (64, 32), (32,), (2, 3, 4), (0,), (1000,)],
          [(256, 512), (512,), (512, 4), (4,), (33, 17, 3)]]


CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=CUDA)])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shapes", SHAPES, ids=[f"{len(s)}-tensors" for s in SHAPES])
def test_torch_get_total_norm_gives_target_lag_bit_for_bit(shapes, dtype, device):
    generator = torch.Generator().manual_seed(len(shapes))
    for scale in (1.0, 1e-3, 1e3):
        online = [(torch.randn(s, generator=generator, dtype=dtype) * scale).to(device)
                  for s in shapes]
        target = [o + (torch.randn(o.shape, generator=generator, dtype=dtype) * scale * 0.01).to(device)
                  for o in online]
        for a, b in ((online, target), (online, online)):
            old, new = _old_target_lag(a, b), _new_target_lag(a, b)
            assert new == old, changed("torch", f"get_total_norm differs from the foreach norms "
                                                f"(target_lag {new!r} != {old!r})")
        old_norm = torch.stack(torch._foreach_norm(online)).norm()
        assert torch.equal(torch.nn.utils.get_total_norm(online, foreach=True), old_norm)


def _updated_agent(group, device="cpu"):
    cfg = TDMPCConfig.from_dict({"group": group, "batch_size": 8, "horizon": 3, "tau": 0.2,
                                 "target_update_every": 1,
                                 "networks": {"hidden_dim": 32, "latent_dim": 16}})
    sym = gymnasium.make("GeoMDP/PointMass2D-v0").unwrapped.symmetry
    agent = TDMPCAgent(cfg, sym, sym.observation_size, sym.action_size, device=device, seed=0)
    g = torch.Generator().manual_seed(0)
    n, h = 8, 3
    batch = TensorDict({
        "observation": torch.randn(n, h, sym.observation_size, generator=g) * 0.2,
        "action": torch.rand(n, h, sym.action_size, generator=g) * 1.4 - 0.7,
        "next": {"observation": torch.randn(n, h, sym.observation_size, generator=g) * 0.2,
                 "reward": torch.rand(n, h, 1, generator=g),
                 "terminated": torch.zeros(n, h, 1, dtype=torch.bool)}}, batch_size=[n, h])
    return agent, batch


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=CUDA)])
@pytest.mark.parametrize("group", ["none", "D8"])
def test_agent_target_lag_is_bit_identical_to_the_foreach_formula(group, device):
    """On a real agent's online and target parameter lists, before and after updates."""
    agent, batch = _updated_agent(group, device)
    lags = []
    for _ in range(4):
        online = list(agent.model.parameters())
        target = list(agent.loss.target_model.parameters())
        lag = agent.target_lag()
        assert lag == _old_target_lag(online, target) == _new_target_lag(online, target), changed(
            "torch", "TDMPCAgent.target_lag differs from the foreach formula it replaced")
        lags.append(lag)
        agent.update(batch)
    assert lags[0] == 0 and 0 < lags[-1] < 1


# --------------------------------------------------------------------------- torchrl


def test_torchrl_extension_loads_with_the_pinned_torch():
    """Prioritised replay (the default) needs TorchRL's compiled segment trees; the run
    refuses it without them (tests/test_train.py), so with the pinned pair they must load."""
    assert prioritized_replay_available(), changed(
        "torchrl", f"its compiled extension (torchrl._torchrl) does not load with torch "
                   f"{torch.__version__}: prioritised replay cannot run")


def _filled_buffer(seed=0, prioritized=True):
    torch.manual_seed(seed)
    buffer = make_replay_buffer(ReplayConfig(capacity=64, prioritized=prioritized), horizon=3,
                                batch_size=4)
    for episode, length in enumerate((10, 7, 12)):
        buffer.extend(TensorDict({"observation": torch.randn(length, 2),
                                  "episode": torch.full((length,), episode)}, [length]))
    return buffer


def test_torchrl_priority_state_round_trips_exactly(tmp_path):
    buffer = _filled_buffer()
    for _ in range(3):  # priorities of sampled slices, as the agent writes them
        batch = buffer.sample().reshape(-1, 3)
        update_priorities(buffer, batch, torch.rand(batch.shape[0]) * 5)
    sampler, n = buffer.sampler, len(buffer)
    with internal("torchrl", "PrioritizedSampler._sum_tree/_min_tree/_max_priority"):
        state = priority_state(sampler, n)
    public = sampler.state_dict()  # the whole trees, deep-copied: the public view
    index = torch.arange(n)
    assert torch.equal(torch.as_tensor(public["_sum_tree"][index]), state["sum"]) and torch.equal(
        torch.as_tensor(public["_min_tree"][index]), state["min"]), changed(
        "torchrl", "PrioritizedSampler._sum_tree/_min_tree differ from its state_dict's trees")
    assert public["_max_priority"] == state["max"] and state["max"][0] is not None, changed(
        "torchrl", "PrioritizedSampler._max_priority differs from its state_dict's")

    save_replay(buffer, tmp_path / "replay.pt")
    loaded = make_replay_buffer(ReplayConfig(capacity=64), horizon=3, batch_size=4)
    load_replay(loaded, tmp_path / "replay.pt")
    again = priority_state(loaded.sampler, n)
    assert torch.equal(again["sum"], state["sum"]) and torch.equal(again["min"], state["min"]) \
        and again["max"] == state["max"], changed("torchrl", "restored priorities differ")
    assert loaded.writer.state_dict() == buffer.writer.state_dict(), changed(
        "torchrl", "the writer's state_dict/load_state_dict no longer round-trip its cursor")
    draws = []
    for b in (buffer, loaded):
        torch.manual_seed(1)
        np.random.seed(1)  # TorchRL's prioritised sampling on CPU draws from numpy
        sample = b.sample()
        draws.append((sample["index"], sample["priority_weight"]))
    assert torch.equal(draws[0][0], draws[1][0]) and torch.equal(draws[0][1], draws[1][1]), changed(
        "torchrl", "a sampler restored from its priorities samples differently from the original")

    fresh = make_replay_buffer(ReplayConfig(capacity=64), horizon=3, batch_size=4)
    restore_priority_state(fresh.sampler, n, state)
    assert fresh.sampler.state_dict()["_max_priority"] == state["max"], changed(
        "torchrl", "writing PrioritizedSampler._max_priority does not set the sampler's maximum")


@pytest.mark.parametrize("within", [False, True])
def test_new_data_gets_the_largest_priority_ever_or_the_largest_held(within, tmp_path):
    """agent.replay.max_priority_within_buffer: TorchRL's default gives new slots the largest
    priority ever written; TD-MPC's buffer the largest among the slots it holds. Kept by a
    checkpoint's save and load."""
    config = ReplayConfig(capacity=64, max_priority_within_buffer=within)

    def extend(buffer, episode, length):
        buffer.extend(TensorDict({"observation": torch.zeros(length, 2),
                                  "episode": torch.full((length,), episode)}, [length]))

    buffer = make_replay_buffer(config, horizon=3, batch_size=4)
    extend(buffer, 0, 10)
    buffer.update_priority(torch.arange(10), torch.where(torch.arange(10) == 4, 50.0, 1.0))
    buffer.update_priority(torch.tensor([4]), torch.tensor([2.0]))  # the largest one lowered
    save_replay(buffer, tmp_path / "replay.pt")
    loaded = make_replay_buffer(config, horizon=3, batch_size=4)
    load_replay(loaded, tmp_path / "replay.pt")
    for b in (buffer, loaded):
        extend(b, 1, 5)
        with internal("torchrl", "PrioritizedSampler._sum_tree"):
            tree = priority_state(b.sampler, 15)["sum"]
        ratio = float(tree[10] / tree[4])  # a new slot against the slot that now holds 2.0
        expected = 1.0 if within else 25.0 ** config.alpha
        assert ratio == pytest.approx(expected, rel=1e-4), changed(
            "torchrl", f"new data's priority with max_priority_within_buffer={within}: "
                       f"{ratio:.3f} x the held maximum, expected {expected:.3f}")
    with pytest.raises(OptionError, match="needs agent.replay.prioritized=true"):
        ReplayConfig(prioritized=False, max_priority_within_buffer=True)


@pytest.mark.parametrize("eps", [1e-8, 1e-6])
def test_priority_eps_sets_how_often_a_zero_error_slot_is_drawn(eps, tmp_path):
    """agent.replay.priority_eps: a slot written with TD error 0 holds eps^alpha, one
    written with error 1 holds (1 + eps)^alpha (TorchRL's eps 1e-8, TD-MPC's 1e-6), and
    a checkpoint's save and load keep both."""
    config = ReplayConfig(capacity=64, priority_eps=eps)
    buffer = make_replay_buffer(config, horizon=3, batch_size=4)
    buffer.extend(TensorDict({"observation": torch.zeros(10, 2),
                              "episode": torch.zeros(10, dtype=torch.long)}, [10]))
    buffer.update_priority(torch.arange(10), (torch.arange(10) % 2).float())
    save_replay(buffer, tmp_path / "replay.pt")
    loaded = make_replay_buffer(config, horizon=3, batch_size=4)
    load_replay(loaded, tmp_path / "replay.pt")
    for b in (buffer, loaded):
        with internal("torchrl", "PrioritizedSampler._sum_tree"):
            tree = priority_state(b.sampler, 10)["sum"]
        assert float(tree[0]) == pytest.approx(eps ** config.alpha, rel=1e-5), changed(
            "torchrl", f"a zero-error slot's priority with eps={eps}: {float(tree[0]):.3g}")
        assert float(tree[1]) == pytest.approx((1 + eps) ** config.alpha, rel=1e-5)
    with pytest.raises(OptionError, match="agent.replay.priority_eps must be > 0"):
        ReplayConfig(priority_eps=0.0)


def test_torchrl_expect_target_updater():
    from torchrl._utils import rl_warnings

    if not rl_warnings():
        pytest.skip("RL_WARNINGS is off: TorchRL does not warn")

    class Loss(LossModule):
        def __init__(self):
            super().__init__()
            self.model = nn.Linear(2, 1)
            self.model_params = TensorDict.from_module(self.model)
            self.target_model_params = TensorDictParams(
                TensorDict.from_module(copy.deepcopy(self.model).requires_grad_(False)),
                no_convert=True)
            expect_target_updater(self, "model")

        def forward(self, td):
            return TensorDict({"loss": self.model(td["x"]).sum()}, [])

    td = TensorDict({"x": torch.randn(3, 2)}, [3])
    with internal("torchrl", "LossModule._has_update_associated"):
        loss = Loss()
    with pytest.warns(UserWarning, match="No target network updater") as record:
        loss(td)
    assert record, changed("torchrl", "a loss awaiting its target updater no longer warns")
    SoftUpdate(loss, tau=0.1)
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        loss(td)
    assert not [w for w in record if "target network updater" in str(w.message)], changed(
        "torchrl", "SoftUpdate no longer clears LossModule._has_update_associated")


# ----------------------------------------------------------------------------- escnn


def _types(group: str, in_fields, out_fields):
    """Field types of a 0-dimensional gspace: each field an irrep id, or "regular"."""
    g = {"D4": escnn_group.dihedral_group(4), "C4": escnn_group.cyclic_group(4),
         "SO2": escnn_group.so2_group(3)}[group]
    space = gspaces.no_base_space(g)

    def rep(field):
        if field == "regular":
            return g.regular_representation
        return g.irrep(*field) if isinstance(field, tuple) else g.irrep(field)

    return (enn.FieldType(space, [rep(f) for f in in_fields]),
            enn.FieldType(space, [rep(f) for f in out_fields]))


# (group, input fields, output fields): one pair; fields of a type interleaved with
# others (not adjacent); several pairs; a continuous group's band-limited irreps.
LAYERS = [
    ("D4", ["regular"] * 3, ["regular"] * 2),
    ("D4", [(0, 0), "regular", (1, 1), (0, 0)], ["regular", (1, 1), (0, 0), "regular"]),
    ("C4", [0, 1, 1, "regular"], [2, "regular", 1]),
    ("SO2", [0, 1, 2, 1], [1, 0, 2]),
]


@pytest.mark.parametrize("spec", LAYERS, ids=[f"{g}-{i}" for i, (g, *_) in enumerate(LAYERS)])
def test_escnn_basis_blocks_describe_the_weights(spec):
    torch.manual_seed(0)
    layer = enn.Linear(*_types(*spec))
    expansion = layer.basisexpansion
    with internal("escnn", "BlocksBasisExpansion._representations_pairs/_weights_ranges/"
                           "block_expansion_<_escape_pair> submodules"):
        blocks = basis_blocks(expansion)
    in_reprs, out_reprs = layer.in_type.representations, layer.out_type.representations
    in_count, out_count = Counter(r.name for r in in_reprs), Counter(r.name for r in out_reprs)

    stops = [0] + [b.weights[1] for b in blocks]
    assert [b.weights[0] for b in blocks] == stops[:-1] and stops[-1] == expansion.dimension() \
        == layer.weights.numel(), changed("escnn", "the pairs' _weights_ranges no longer tile "
                                                   "the weight vector in _representations_pairs order")
    for b in blocks:
        size = b.sampled_basis.shape[0] * in_count[b.in_name] * out_count[b.out_name]
        assert b.weights[1] - b.weights[0] == size, changed(
            "escnn", f"pair {b.in_name}->{b.out_name}: its range is not n_out x n_in x basis")

    # The layout against escnn's public per-coefficient description.
    info = list(expansion.get_basis_info())
    in_fields = {name: [i for i, r in enumerate(in_reprs) if r.name == name] for name in in_count}
    out_fields = {name: [o for o, r in enumerate(out_reprs) if r.name == name] for name in out_count}
    for b in blocks:
        n_in, dim = in_count[b.in_name], b.sampled_basis.shape[0]
        for k in range(b.weights[0], b.weights[1]):
            o, rest = divmod(k - b.weights[0], n_in * dim)
            attr = info[k]
            assert (attr["in_repr"], attr["out_repr"]) == (b.in_name, b.out_name) and (
                attr["out_field_position"], attr["in_field_position"]) == (
                out_fields[b.out_name][o], in_fields[b.in_name][rest // dim]), changed(
                "escnn", f"coefficient {k} is not where the private layout puts it "
                         f"(get_basis_info says {attr['in_repr']}->{attr['out_repr']})")

    # The layout against escnn's own expansion: rebuild the matrix from the blocks.
    weights = torch.randn(expansion.dimension())
    expected = expansion(weights)[..., 0]
    in_channels = {name: [] for name in in_count}
    out_channels = {name: [] for name in out_count}
    for reprs, channels in ((in_reprs, in_channels), (out_reprs, out_channels)):
        start = 0
        for r in reprs:
            channels[r.name].extend(range(start, start + r.size))
            start += r.size
    rebuilt = torch.zeros_like(expected)
    for b in blocks:
        basis = b.sampled_basis[..., 0]  # [basis, out_size, in_size]
        n_out, n_in = out_count[b.out_name], in_count[b.in_name]
        coefficients = weights[b.weights[0]:b.weights[1]].view(n_out, n_in, -1)
        block = torch.einsum("oib,bpq->opiq", coefficients, basis).reshape(
            n_out * basis.shape[1], n_in * basis.shape[2])
        rows, cols = out_channels[b.out_name], in_channels[b.in_name]
        rebuilt[torch.tensor(rows)[:, None], torch.tensor(cols)[None, :]] = block
    assert torch.allclose(rebuilt, expected, atol=1e-6), changed(
        "escnn", "the blocks' bases and ranges no longer rebuild BlocksBasisExpansion's matrix")


def test_escnn_own_basis_expansion():
    types = _types("D4", ["regular"] * 2, ["regular"] * 2)
    a, b = enn.Linear(*types), enn.Linear(*types)
    shared = a.basisexpansion
    with internal("escnn", "Linear._basisexpansion"):
        own_basis_expansion(a)
    assert a.basisexpansion is not shared and a.basisexpansion == shared, changed(
        "escnn", "Linear.basisexpansion does not read the attribute own_basis_expansion writes")
    assert any(m is a.basisexpansion for m in child_modules(a)), changed(
        "escnn", "the copied basis expansion is not registered as the layer's submodule")
    ours = {t.data_ptr() for t in a.basisexpansion.buffers()}
    assert ours and not ours & {t.data_ptr() for t in b.basisexpansion.buffers()}, \
        "the copy shares buffers with another layer"
    a.double()
    assert all(t.dtype == torch.float32 for t in b.basisexpansion.buffers() if t.is_floating_point())
    assert torch.equal(a.expand_parameters()[0], a.basisexpansion(a.weights)[..., 0]), changed(
        "escnn", "Linear.expand_parameters no longer uses the module behind basisexpansion")


def test_escnn_basis_expansion_key():
    layer = enn.Linear(*_types("D4", ["regular", (0, 0)], ["regular", (1, 1)]))
    names = [name for name, m in layer.named_children() if m is layer.basisexpansion]
    assert names == [BASIS_EXPANSION], changed(
        "escnn", f"Linear's basis expansion is registered as {names}, not {BASIS_EXPANSION!r}")
    keys = layer.state_dict()
    flagged = {k for k in keys if is_basis_expansion_key(k)}
    assert flagged and flagged == {k for k in keys if k.startswith(BASIS_EXPANSION + ".")}


def test_escnn_linear_buffers():
    layer = enn.Linear(*_types("D4", ["regular", (0, 0)], ["regular", (1, 1), (0, 0)]))
    names = {mode: None for mode in ("train", "eval")}
    for mode in names:
        layer.train(mode == "train")
        names[mode] = {k.rsplit(".", 1)[-1] for k in layer.state_dict()
                       if not is_basis_expansion_key(k)} - {"weights", "bias"}
    assert names["train"] <= names["eval"] == set(LINEAR_BUFFERS), changed(
        "escnn", f"Linear's own buffers are {sorted(names['eval'])}, not {sorted(LINEAR_BUFFERS)}")
    assert all(is_linear_buffer(n) for n in LINEAR_BUFFERS) and not is_linear_buffer("weights")
    assert not is_linear_buffer("bias")


def test_escnn_bias_expansion():
    torch.manual_seed(0)
    layer = enn.Linear(*_types("D4", ["regular"] * 2, ["regular", (1, 1), (0, 0)]))
    with torch.no_grad():
        layer.bias.normal_()
    with internal("escnn", "Linear.bias_expansion"):
        matrix = bias_expansion(layer)
    _, expected = layer.expand_parameters()
    assert matrix.shape == (layer.out_type.size, layer.bias.numel()) and torch.allclose(
        matrix @ layer.bias, expected, atol=1e-6), changed(
        "escnn", "Linear.bias_expansion @ Linear.bias is not the bias expand_parameters() gives")


def test_escnn_buffers_are_what_an_agent_leaves_out_of_its_checkpoints():
    """Every entry of an escnn ``Linear`` in an equivariant agent's state dict (online and
    target) is one of its coefficients (``weights``, ``bias``: saved) or one that escnn
    rebuilds with the layer, and is recognised as such."""
    agent, _ = _updated_agent("D8")
    entries = [k for k in agent.loss.state_dict() if ".layer." in k]
    coefficients = [k for k in entries if k.rsplit(".", 1)[-1] in ("weights", "bias")]
    rebuilt = [k for k in entries if rebuilt_with_networks(k)]
    assert coefficients and rebuilt and not set(coefficients) & set(rebuilt)
    assert sorted(coefficients + rebuilt) == sorted(entries), changed(
        "escnn", "Linear has state-dict entries that agents.compat.escnn does not name: "
                 f"{sorted(set(entries) - set(coefficients) - set(rebuilt))[:3]}")
    assert any(k.endswith(".bias_expansion") for k in rebuilt)


def test_escnn_solves_null_spaces_with_scipy_even_beside_scikit_learn(monkeypatch):
    """escnn switches to scikit-learn's randomized SVD whenever it can import it, and
    scikit-learn >= 1.2 refuses the np.matrix escnn passes (a GPU machine's image had
    it: no D8 network could be built there). use_exact_null_space, called when
    agents.compat.escnn is imported (every module of agents that builds escnn layers
    imports it), puts escnn back on scipy's exact SVD."""
    from escnn.group import _numerical

    # In a fresh process, as if scikit-learn were installed: importing the agent's groups
    # puts escnn back on scipy (CI has no scikit-learn, so in-process this cannot fail).
    fresh = subprocess.run([sys.executable, "-c",
                            "from escnn.group import _numerical as n; n.randomized_svd = object(); "
                            "import agents.nn.escnn_groups; print(n.randomized_svd)"],
                           capture_output=True, text=True, check=False)
    assert fresh.stdout.strip() == "None", fresh.stderr[-1000:] or changed(
        "escnn", "escnn.group._numerical.randomized_svd is still used after agents is imported")

    def like_scikit_learn(matrix, **kwargs):
        raise TypeError("np.matrix is not supported")

    monkeypatch.setattr(_numerical, "randomized_svd", like_scikit_learn)
    use_exact_null_space()
    basis = _numerical.null(np.matrix(np.diag([1.0, 0.0, 2.0])), use_sparse=False)
    assert basis.shape == (3, 1) and np.isclose(abs(basis[1, 0]), 1.0), changed(
        "escnn", "_numerical.null no longer falls back to scipy when randomized_svd is None")


# ------------------------------------------------------------------------- gymnasium


def test_gymnasium_observe():
    env = gymnasium.make("Reacher-v5").unwrapped
    assert can_observe(env) and not can_observe(gymnasium.Env()), changed(
        "gymnasium", "a MuJoCo env no longer has MujocoEnv._get_obs")
    obs, _ = env.reset(seed=0)
    with internal("gymnasium", "MujocoEnv._get_obs"):
        np.testing.assert_array_equal(observe(env), obs)
    stepped = env.step(np.array([0.3, -0.2], dtype=np.float32))[0]
    assert np.array_equal(observe(env), stepped) and observe(env) is not observe(env), changed(
        "gymnasium", "MujocoEnv._get_obs is not the observation step() returns (or is not fresh)")


def test_gymnasium_restore_random_state():
    env = gymnasium.make("Reacher-v5").unwrapped
    env.reset(seed=7)
    env.np_random.random()  # a generator part-way through its stream
    saved = random_state(env)
    expected = copy.deepcopy(saved[0]).random(3)
    env.reset(seed=11)
    assert env.np_random_seed == 11
    env.np_random = np.random.default_rng(0)
    assert env.np_random_seed == -1, changed(
        "gymnasium", "the np_random setter no longer records the seed as -1: "
                     "restore_random_state may no longer be needed")
    with internal("gymnasium", "Env._np_random_seed"):
        restore_random_state(env, saved)
    assert env.np_random_seed == 7 and env.np_random is saved[0], changed(
        "gymnasium", "writing Env._np_random_seed does not set np_random_seed")
    np.testing.assert_array_equal(env.np_random.random(3), expected)
