"""The networks of TD-MPC, plain or G-equivariant from one definition.

``build_networks(config, symmetry)`` reads a task's symmetry declaration and
builds the encoder, latent dynamics, reward, twin Q and policy. With
``config.group = None`` every layout is a plain size and every network an MLP
(and no declaration is needed: ``build_networks(config, None, obs_size, action_size)``);
with a group, the observation and action layouts are the declared fields as
escnn field types, hidden layers and the latent state are regular fields, and
the same ``FieldMLP`` becomes equivariant (vector outputs) or invariant (scalar
outputs). Each component can be plain or equivariant on its own
(``config.equivariant``), for the paper's ablation.

Width strategies turn a plain width W into copies of the regular representation
of G: ``sqrt`` uses W / sqrt(|G|) copies (about the plain network's number of
free parameters, |G| times its FLOPs), ``linear`` W / |G| copies (the plain
network's tensor width and FLOPs, |G| times fewer parameters).
"""

from __future__ import annotations

import math
import typing
from dataclasses import dataclass, field

import torch
from torch import nn

from agents.nn.activations import ACTIVATIONS
from agents.nn.escnn_groups import GROUP_NAMES, AgentGroup, field_type, group_for_task, is_group_name
from agents.nn.layers import LINEAR_KINDS, make_linear, norm_and_activation
from agents.nn.layout import Layout, concat, layout_size
from agents.nn.spectral import Quadrature
from agents.options import OptionError, check, key, option, unknown
from geomdp_envs.symmetry import Field, Symmetry

WIDTH_STRATEGIES = ("sqrt", "linear")
COMPONENTS = ("transition", "q", "policy")
LAYER_NORMS = ("every", "q_input")
INITS = ("default", "orthogonal")


@dataclass
class Architecture:
    """Sizes are those of the plain network; equivariant ones follow ``width_strategy``."""

    KEY: typing.ClassVar[str] = "agent.networks"
    latent_dim: int = option(64, low=1)
    hidden_dim: int = option(256, low=1)
    hidden_layers: int = option(2, low=1)
    activation: str = option("elu", choices=tuple(ACTIVATIONS))
    num_q: int = option(2, low=1)
    # Equivariant layers into regular fields: dense (escnn's expanded matrix), fourier
    # (block-diagonal in the irrep basis), or auto: fourier for sqrt width, where it
    # is faster, dense for linear width (few fields), where it is not (BENCHMARKS.md).
    layers: str = option("auto", choices=("auto", *LINEAR_KINDS))
    # Continuous groups (SO2, O2, SO3, O3): hidden fields keep frequencies <= max_frequency,
    # nonlinearities sample a grid exact to grid_frequency (null: agents.nn.escnn_groups' defaults).
    max_frequency: int | None = None
    grid_frequency: int | None = None
    # Where this agent departs from TD-MPC's networks, each restorable on its own (issue 37,
    # docs/tdmpc_differences.md). The encoder's hidden layers and width (null: as every other
    # head's; TD-MPC: 1 layer of 256 beside 512 elsewhere).
    encoder_layers: int | None = option(None, low=1)
    encoder_dim: int | None = option(None, low=1)
    # every: LayerNorm before every hidden nonlinearity; q_input: TD-MPC's, only after the
    # Q's first layer, followed by tanh there (the other heads: linear and activation only).
    layer_norm: str = option("every", choices=LAYER_NORMS)
    # default: PyTorch's and escnn's; orthogonal: TD-MPC's (orthogonal weights, zero biases),
    # for plain layers only (escnn's basis coefficients have no orthogonal rule).
    init: str = option("default", choices=INITS)

    def __post_init__(self) -> None:
        check(self)

    def hidden_blocks(self, head: str) -> tuple[int, list[tuple[bool, str]]]:
        """A head's plain hidden width and, per hidden layer, (LayerNorm or not, nonlinearity);
        ``head`` is ``encoder``, ``dynamics``, ``reward``, ``q`` or ``policy``."""
        if head == "encoder":
            depth, width = self.encoder_layers or self.hidden_layers, self.encoder_dim or self.hidden_dim
        else:
            depth, width = self.hidden_layers, self.hidden_dim
        if self.layer_norm == "every":
            return width, [(True, self.activation)] * depth
        tdmpc_q_input = [head == "q" and i == 0 for i in range(depth)]
        return width, [(first, "tanh" if first else self.activation) for first in tdmpc_q_input]


@dataclass
class NetworkConfig:
    """Everything ``build_networks`` needs, as the ``agent`` section nests it: which group
    the networks respect and how (at the top of ``agent``), and their architecture
    (``agent.networks``). ``TDMPCConfig`` extends it, so an agent's config is passed as is."""

    KEY: typing.ClassVar[str] = "agent"
    group: str | None = None  # none | C<N> D<N> SO2 O2 | octahedral icosahedral SO3 O3 (the task decides)
    width_strategy: str = option("sqrt", choices=WIDTH_STRATEGIES)
    # Per component (transition: encoder, dynamics, reward; q; policy), for the ablation;
    # a component left out is equivariant.
    equivariant: dict[str, bool] = option(factory=lambda: {name: True for name in COMPONENTS})
    # A continuous group that is only an approximate symmetry of the task (O2 on
    # PointMass2D, whose walls keep only D4) is refused unless this is set.
    allow_approximate: bool = False
    networks: Architecture = field(default_factory=Architecture)

    def __post_init__(self) -> None:
        if self.group == "none":
            self.group = None
        check(self)
        if self.group is not None and not is_group_name(self.group):
            raise OptionError(f"{key(NetworkConfig, 'group')}={self.group!r}; valid: none, "
                              f"{GROUP_NAMES} (the task decides which apply)")
        for name in self.equivariant:
            if name not in COMPONENTS:
                raise unknown(f"{key(NetworkConfig, 'equivariant')}.{name}", COMPONENTS)
        use = {name: self.equivariant.get(name, True) for name in COMPONENTS}
        if self.group is not None and (use["q"] or use["policy"]) and not use["transition"]:
            raise OptionError("agent.equivariant: an equivariant Q or policy needs an "
                              "equivariant latent state: make the transition (encoder, dynamics, "
                              "reward) equivariant too")
        if self.networks.init == "orthogonal" and self.group is not None and any(use.values()):
            raise OptionError(f"{key(Architecture, 'init')}=orthogonal applies to plain layers "
                              f"only (agent.group=none, or every component of agent.equivariant "
                              f"false); equivariant layers have no orthogonal rule: use "
                              f"{key(Architecture, 'init')}=default")

    def linear_kind(self) -> str:
        """The hidden layers' kind once ``auto`` is decided."""
        if self.networks.layers != "auto":
            return self.networks.layers
        return "fourier" if self.width_strategy == "sqrt" else "dense"


def regular_copies(width: int, group: AgentGroup, strategy: str) -> int:
    """How many hidden fields (regular, or band-limited for a continuous group) stand
    in for ``width`` plain channels: the field size plays the role of |G|."""
    divisor = math.sqrt(group.field_size) if strategy == "sqrt" else group.field_size
    return max(1, round(width / divisor))


class FieldMLP(nn.Module):
    """Linear -> LayerNorm -> activation blocks (``blocks``: per hidden layer, LayerNorm or
    not and the nonlinearity's name), then a linear output layer.

    Plain when the layouts are sizes, equivariant when they are field types.
    Takes and returns plain tensors [..., size].
    """

    def __init__(self, in_layout: Layout, hidden: list[Layout], out_layout: Layout,
                 blocks: list[tuple[bool, str]], linear_kind: str = "dense",
                 grid: Quadrature | None = None) -> None:
        super().__init__()
        layers, previous = [], in_layout
        for layout, (norm, name) in zip(hidden, blocks, strict=True):
            layers += [make_linear(previous, layout, kind=linear_kind),
                       *norm_and_activation(layout, name, grid, layer_norm=norm)]
            previous = layout
        layers.append(make_linear(previous, out_layout, kind=linear_kind))
        self.net = nn.Sequential(*layers)
        self.in_layout, self.out_layout = in_layout, out_layout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)

    def zero_output_layer(self) -> FieldMLP:
        """Start with an output of exactly zero (TD-MPC's reward and Q heads).

        Zero basis coefficients expand to a zero matrix, so this holds for
        equivariant layers too.
        """
        with torch.no_grad():
            for p in self.net[-1].parameters():
                p.zero_()
        return self

    def orthogonal_init(self) -> FieldMLP:
        """TD-MPC's initialisation: orthogonal weights, zero biases (plain layers only)."""
        if not isinstance(self.in_layout, int):
            raise TypeError("orthogonal initialisation is defined for plain networks only")
        with torch.no_grad():
            for layer in self.net:
                if isinstance(layer, nn.Linear):
                    nn.init.orthogonal_(layer.weight)
                    nn.init.zeros_(layer.bias)
        return self


class Space:
    """The layouts one component works with: plain sizes, or field types of a group."""

    def __init__(self, observation: tuple[Field, ...], action: tuple[Field, ...],
                 group: AgentGroup | None, config: NetworkConfig) -> None:
        self.group, self.config = group, config
        self.observation = self._declared(observation)
        self.action = self._declared(action)
        self.latent = self.regular(config.networks.latent_dim)
        self.scalar = self.trivial(1)

    def _declared(self, fields: tuple[Field, ...]) -> Layout:
        if self.group is None:
            return fields[-1].stop
        return field_type(self.group, fields)

    def regular(self, width: int) -> Layout:
        if self.group is None:
            return width
        copies = regular_copies(width, self.group, self.config.width_strategy)
        return self.group.gspace.type(*[self.group.regular] * copies)

    def trivial(self, n: int) -> Layout:
        return n if self.group is None else self.group.gspace.type(*[self.group.trivial] * n)

    def mlp(self, head: str, in_layout: Layout, out_layout: Layout) -> FieldMLP:
        """The network of one of TD-MPC's heads (encoder, dynamics, reward, q, policy), as
        ``agent.networks`` shapes it."""
        architecture = self.config.networks
        grid = None if self.group is None else self.group.quadrature
        width, blocks = architecture.hidden_blocks(head)
        network = FieldMLP(in_layout, [self.regular(width)] * len(blocks), out_layout, blocks,
                           self.config.linear_kind(), grid)
        return network.orthogonal_init() if architecture.init == "orthogonal" else network


def squash(x: torch.Tensor, fields: tuple[Field, ...]) -> torch.Tensor:
    """Map R^n onto the action domain, equivariantly.

    Each vector field is scaled by tanh(|x|)/|x| into the unit ball (a rotation
    commutes with it, unlike an element-wise tanh, which only signed
    permutations commute with); scalar fields go through tanh, which is odd and
    so commutes with sign changes.
    """
    parts = []
    for f in fields:
        v = x[..., f.start:f.stop]
        if f.size == 1:
            parts.append(torch.tanh(v))
        else:
            norm = v.norm(dim=-1, keepdim=True).clamp_min(1e-6)
            parts.append(v * (torch.tanh(norm) / norm))
    return torch.cat(parts, dim=-1)


def project(x: torch.Tensor, fields: tuple[Field, ...], radius: float = 1.0) -> torch.Tensor:
    """The nearest point of the action domain scaled by ``radius``: vector fields
    longer than ``radius`` are scaled back onto that sphere, scalar fields clipped
    to [-radius, radius].

    The equivariant counterpart of clamping each coordinate (the action domain
    with radius 1; TD-MPC's noise clip with radius 0.3).
    """
    parts = []
    for f in fields:
        v = x[..., f.start:f.stop]
        if f.size == 1:
            parts.append(v.clamp(-radius, radius))
        else:
            parts.append(v * (radius / v.norm(dim=-1, keepdim=True).clamp_min(radius)))
    return torch.cat(parts, dim=-1)


@dataclass
class Networks:
    """The five networks of TD-MPC and what they were built from."""

    encoder: FieldMLP
    dynamics: FieldMLP
    reward: FieldMLP
    qs: nn.ModuleList
    policy: FieldMLP
    group: AgentGroup | None
    exact: bool
    config: NetworkConfig
    action_fields: tuple[Field, ...]  # the declared ones with a group, scalars without

    def modules(self) -> dict[str, nn.Module]:
        return {"encoder": self.encoder, "dynamics": self.dynamics, "reward": self.reward,
                "qs": self.qs, "policy": self.policy}

    def parameter_counts(self) -> dict[str, int]:
        return {name: sum(p.numel() for p in m.parameters()) for name, m in self.modules().items()}


def plain_fields(size: int) -> tuple[Field, ...]:
    """``size`` scalar fields: a vector seen without any group action (box actions)."""
    return tuple(Field(f"x{i}", "trivial", i, i + 1) for i in range(size))


def build_networks(config: NetworkConfig, symmetry: Symmetry | None,
                   observation_size: int | None = None, action_size: int | None = None) -> Networks:
    """TD-MPC's networks for a task, equivariant to ``config.group`` where asked.

    A plain agent needs no declaration: pass ``symmetry=None`` and the sizes.
    """
    if config.group in (None, "none"):
        group, exact = None, True
        observation = plain_fields(observation_size or symmetry.observation_size)
        action = plain_fields(action_size or symmetry.action_size)
    elif symmetry is None:
        raise ValueError(f"group {config.group} needs a task that declares its symmetry "
                         "(a GeoMDP task); use group=none for other environments")
    else:
        group, exact = group_for_task(config.group, symmetry, config.networks.max_frequency,
                                      config.networks.grid_frequency, config.allow_approximate)
        observation, action = symmetry.observation, symmetry.action
    use = {name: group is not None and config.equivariant.get(name, True) for name in COMPONENTS}
    spaces = {name: Space(observation, action, group if use[name] else None, config)
              for name in COMPONENTS}
    latent = spaces["transition"].latent

    def as_seen_by(name: str, layout: Layout) -> Layout:
        """A plain component sees an equivariant layout as a plain vector."""
        return layout if use[name] else layout_size(layout)

    t, q, p = spaces["transition"], spaces["q"], spaces["policy"]
    q.latent, p.latent = as_seen_by("q", latent), as_seen_by("policy", latent)
    return Networks(
        encoder=t.mlp("encoder", t.observation, latent),
        dynamics=t.mlp("dynamics", concat(latent, t.action), latent),
        reward=t.mlp("reward", concat(latent, t.action), t.scalar).zero_output_layer(),
        qs=nn.ModuleList(q.mlp("q", concat(q.latent, q.action), q.scalar).zero_output_layer()
                         for _ in range(config.networks.num_q)),
        policy=p.mlp("policy", p.latent, p.action),
        group=group, exact=exact, config=config, action_fields=action,
    )
