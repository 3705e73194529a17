"""The TD-MPC agent: world model, planner, loss, target updates and optimisers."""

from __future__ import annotations

import typing
from dataclasses import dataclass, field
from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.objectives import SoftUpdate

from agents.compat.escnn import is_basis_expansion_key, is_linear_buffer
from agents.nn.escnn_groups import GROUP_NAMES
from agents.nn.expansion import expansion_scope
from agents.nn.layers import dense_equivariant_layers
from agents.nn.networks import NetworkConfig, build_networks
from agents.nn.spectral import GridActivation
from agents.options import OptionError, check, from_dict, key, option
from agents.tdmpc.augmentation import SliceAugmentation, is_augmentation_group_name
from agents.tdmpc.loss import LossConfig, TDMPCLoss
from agents.tdmpc.planner import MPPIPlanner, NoiseSource, PlannerConfig, PlanValues
from agents.tdmpc.replay import ReplayConfig
from agents.tdmpc.world_model import WorldModel
from geomdp_envs.symmetry import Symmetry


def rebuilt_with_networks(key: str) -> bool:
    """Whether a state-dict entry is one of escnn's rebuildable buffers (not saved): in
    every equivariant layer (``EquivariantLinear.layer``), the basis, the bias's change of
    basis, and its eval-mode expansion caches, which this code never uses. All are
    rebuilt with the networks, and they are most of an agent's bytes. Their names are
    escnn's (``agents.compat.escnn``)."""
    return is_basis_expansion_key(key) or (".layer." in key and is_linear_buffer(key.rsplit(".", 1)[-1]))


@dataclass
class Schedule:
    """Linear interpolation from ``start`` to ``end`` over ``steps`` agent steps."""

    KEY: typing.ClassVar[str] = "agent.std_schedule"
    start: float = option(low=0)
    end: float = option(low=0)
    steps: int = option(low=0)

    def __post_init__(self) -> None:
        check(self)

    def __call__(self, step: int) -> float:
        if self.steps <= 0:
            return self.end
        mix = min(max(step / self.steps, 0.0), 1.0)
        return self.start + mix * (self.end - self.start)


@dataclass
class TDMPCConfig(NetworkConfig):
    """TD-MPC's hyperparameters, nested as the ``agent`` section of a run's config. The
    planner's, losses', replay's and schedules' defaults are TD-MPC's (Hansen et al. 2022);
    the networks' (latent 64, width 256, ``sqrt``) are neither preset's, and a run's preset
    (``configs/agent/``) sets every value. It extends ``NetworkConfig``: the agent's config
    is what ``build_networks`` takes."""

    KEY: typing.ClassVar[str] = "agent"
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    replay: ReplayConfig = field(default_factory=ReplayConfig)
    horizon: int = option(5, low=1)
    horizon_schedule: int = option(25_000, low=0)  # agent steps to grow the horizon from 1 to H (0: H)
    std_schedule: Schedule = field(default_factory=lambda: Schedule(0.5, 0.05, 25_000))
    lr: float = option(1e-3, low=0, low_open=True)
    batch_size: int = option(512, low=1)
    tau: float = option(0.01, low=0, low_open=True, high=1)
    target_update_every: int = option(2, low=1)
    grad_clip_norm: float = option(10.0, low=0, low_open=True)
    # Replayed slices moved by a random element of a symmetry group (agents.tdmpc.augmentation):
    # none | auto (the largest exact group that keeps actions in their domain) | a subgroup of it
    augment: str = "none"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.augment not in ("none", "auto") and not is_augmentation_group_name(self.augment):
            raise OptionError(f"{key(TDMPCConfig, 'augment')}={self.augment!r}; valid: none, "
                              f"auto, or a group ({GROUP_NAMES}; the task decides which apply)")
        if self.replay.capacity < self.batch_size * self.horizon:
            raise OptionError(f"{key(ReplayConfig, 'capacity')} ({self.replay.capacity}) must hold "
                              f"at least one batch of slices (batch_size x horizon = "
                              f"{self.batch_size * self.horizon})")

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TDMPCConfig:
        """Build from nested plain data (the ``agent`` section of a Hydra config)."""
        return from_dict(cls, data)


AUGMENT_SEED = 1_000_003  # offset of the augmentation generator's seed from the agent's


def _probe(size: int) -> torch.Tensor:
    return torch.randn(size, generator=torch.Generator().manual_seed(0), dtype=torch.float64)


class TDMPCAgent:
    """Acts by planning with the world model; learns from replayed slices."""

    def __init__(self, config: TDMPCConfig, symmetry: Symmetry | None,
                 observation_size: int, action_size: int,
                 device: torch.device | str = "cpu", seed: int = 0) -> None:
        self.config, self.device = config, torch.device(device)
        self.observation_size, self.action_size = observation_size, action_size
        self.networks = build_networks(config, symmetry, observation_size, action_size)
        self.action_fields = self.networks.action_fields
        self.model = WorldModel(self.networks, self.action_fields, noise_clip=config.loss.noise_clip,
                                straight_through=config.loss.straight_through).to(self.device)
        self.loss = TDMPCLoss(self.model, config.loss).to(self.device)
        self.target_updater = SoftUpdate(self.loss, tau=config.tau)
        policy_params = list(self.model.policy.parameters())
        policy_ids = {id(p) for p in policy_params}
        # Fused Adam: one kernel over all parameters (the per-parameter loop's dispatch
        # dominates at these sizes). Writes that bypass version counters are harmless:
        # nothing here caches on them (see agents.nn.expansion.expansion_scope).
        self.model_optimizer = torch.optim.Adam(
            [p for p in self.model.parameters() if id(p) not in policy_ids], lr=config.lr,
            fused=True)
        self.policy_optimizer = torch.optim.Adam(policy_params, lr=config.lr, fused=True)
        self.planner = MPPIPlanner(self.model, config.planner, config.loss.policy_noise)
        self.generator = torch.Generator().manual_seed(seed)
        self.noise = NoiseSource(self.generator)
        self.updates = 0
        self.horizon_schedule = Schedule(1, config.horizon, config.horizon_schedule)
        # its own stream: the agent's generator (warm-up actions, planner noise) has ``seed``
        self.augmentation = (None if config.augment == "none"
                             else SliceAugmentation(config.augment, symmetry, seed + AUGMENT_SEED))

    def random_action(self) -> torch.Tensor:
        """A uniform action of the agent's action domain (unit ball per vector field), the
        warm-up's, from the agent's own generator: checkpointed with it, so a resumed
        warm-up draws what an uninterrupted one would (``Symmetry.sample_action`` is the
        same distribution from a numpy generator, for code without an agent)."""
        out = []
        for f in self.action_fields:
            if f.size == 1:
                out.append(torch.rand(1, generator=self.generator) * 2 - 1)
            else:
                v = torch.randn(f.size, generator=self.generator)
                radius = torch.rand(1, generator=self.generator) ** (1 / f.size)
                out.append(v / v.norm() * radius)
        return torch.cat(out)

    def start_episode(self) -> None:
        """Forget the planner's warm start: a new episode's first plan starts afresh."""
        self.planner.reset()

    def checkpoint_bytes(self) -> int:
        """About what a checkpoint of the agent holds: the parameters four times (online,
        target, and the optimisers' two moments); what disk checks budget for."""
        return 4 * sum(p.numel() * p.element_size() for p in self.model.parameters())

    def horizon(self, step: int) -> int:
        return int(round(self.horizon_schedule(step)))

    def act(self, obs: torch.Tensor, step: int, explore: bool,
            noise: NoiseSource | None = None) -> torch.Tensor:
        """Plan an action for ``obs``; ``step`` (agent steps) drives the schedules. The
        planner's randomness comes from ``noise`` (default: the agent's own generator)."""
        return self.act_with_values(obs, step, explore, noise)[0]

    def act_with_values(self, obs: torch.Tensor, step: int, explore: bool,
                        noise: NoiseSource | None = None) -> tuple[torch.Tensor, PlanValues]:
        """:meth:`act`'s action, and what the plan valued its best candidates at (for
        replays that ask why the planner chose what it did)."""
        obs = obs.to(self.device, torch.float32)
        # Every equivariant weight expanded once for the whole plan, from the current
        # parameters (updates happen between calls, never inside one).
        with torch.no_grad(), expansion_scope(self.model):
            return self.planner.plan_with_values(
                obs, horizon=self.horizon(step), min_std=self.config.std_schedule(step),
                explore=explore, noise=self.noise if noise is None else noise)

    def _as_model_input(self, obs: torch.Tensor) -> torch.Tensor:
        return obs.to(self.device, next(self.model.parameters()).dtype)

    @torch.no_grad()
    def policy_action(self, obs: torch.Tensor) -> torch.Tensor:
        """The learned policy's action for ``obs`` (its mean, no planning): what the
        planner seeds part of its samples with, and what the TD targets bootstrap on."""
        with expansion_scope(self.model):
            return self.model.pi(self.model.encode(self._as_model_input(obs)))

    @torch.no_grad()
    def value(self, obs: torch.Tensor) -> torch.Tensor:
        """The agent's estimate of the discounted return from ``obs``: min_i Q_i(z, pi(z)),
        z = h(obs), the quantity its TD targets bootstrap on (``[...]`` for ``obs [..., n]``)."""
        return self.q_heads(obs).min(dim=0).values

    @torch.no_grad()
    def q_heads(self, obs: torch.Tensor) -> torch.Tensor:
        """Every Q head's Q_i(z, pi(z)), z = h(obs), stacked (``[num_q, ...]`` for
        ``obs [..., n]``): whether :meth:`value`'s minimum is what makes it low or high."""
        with expansion_scope(self.model):
            z = self.model.encode(self._as_model_input(obs))
            return self.model.q(z, self.model.pi(z)).squeeze(-1)

    @torch.no_grad()
    def predicted_reward(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """The reward model's prediction for taking ``action`` at ``obs`` (per agent step,
        action repeats summed, as replay stores rewards; ``[...]`` for ``obs [..., n]``)."""
        with expansion_scope(self.model):
            z = self.model.encode(self._as_model_input(obs))
            return self.model.reward(z, self._as_model_input(action)).squeeze(-1)

    def update(self, batch: TensorDictBase) -> tuple[dict[str, float], torch.Tensor]:
        """One gradient step on a [batch, horizon] TensorDict. Returns the losses and
        health metrics, and each slice's new replay priority (TD-MPC's TD error). With
        ``agent.augment``, the slices are moved by random group elements first."""
        if batch["observation"].dtype != torch.float32:  # float64 from MuJoCo's envs (Reacher-v5)
            batch = batch.apply(lambda t: t.float() if t.is_floating_point() else t)
        if self.augmentation is not None:
            batch = self.augmentation(batch)
        losses = self.loss(batch.to(self.device))
        self.model_optimizer.zero_grad(set_to_none=True)
        self.policy_optimizer.zero_grad(set_to_none=True)
        (losses["loss_model"] + losses["loss_pi"]).backward()
        clip = self.config.grad_clip_norm
        # The optimisers' parameter lists, not ``Module.parameters()``: walking an escnn
        # network's modules is slow (``agents.nn.parameters.submodules``).
        model_grad, policy_grad = (torch.nn.utils.clip_grad_norm_(
            [p for g in optimizer.param_groups for p in g["params"]], clip, foreach=True)
            for optimizer in (self.model_optimizer, self.policy_optimizer))
        self.model_optimizer.step()
        self.policy_optimizer.step()
        self.updates += 1
        if self.updates % self.config.target_update_every == 0:
            self.target_updater.step()
        metrics = {k: float(losses[k].detach()) for k in (
            "loss_model", "loss_pi", "consistency", "reward_error", "value_error", "q_mean",
            "td_target_mean")}
        metrics.update(model_grad_norm=float(model_grad), policy_grad_norm=float(policy_grad))
        return metrics, losses["priority"]

    @torch.no_grad()
    def basis_fingerprints(self) -> dict[str, torch.Tensor]:
        """Each equivariant layer's map applied to a fixed probe, from the current
        coefficients: escnn computes some bases, transforms and irreps numerically
        (and caches them on disk), and checkpoints store the coefficients and the dense
        layers' bases only (``bases``), so a resume checks that the layers turn the same
        coefficients into the same maps: the Fourier layers' transforms, and the
        continuous groups' sampling grids, built from escnn's irreps, included.

        The map is applied by the layer's own forward (W p + b), not by expanding W:
        the same quantity, 20-50x cheaper for the irrep-basis layers of the paper
        preset (BENCHMARKS.md), and it is computed at every checkpoint."""
        out = {}
        dtype = next(self.model.parameters()).dtype
        for name, module in self.model.named_modules():
            if hasattr(module, "expand") and hasattr(module, "in_type"):
                probe = _probe(module.in_type.size).to(self.device, dtype)[None]
                out[name] = module(probe)[0].double().cpu()
            elif isinstance(module, GridActivation):  # sampled from escnn's irreps
                out[name] = module.to_grid.double().cpu().T @ _probe(module.to_grid.shape[0])
        return out

    def bases(self) -> dict[str, list[torch.Tensor]]:
        """The bases each dense equivariant layer applies, by module name (the online
        model's; the target's are the same): saved with the coefficients, so that a
        resume applies the bases they were trained with, whichever basis of the same
        space escnn solves for on the resuming machine."""
        return {name: [basis.detach().cpu() for basis in layer.bases()]
                for name, layer in dense_equivariant_layers(self.model).items()}

    def adopt_bases(self, saved: dict[str, list[torch.Tensor]]) -> None:
        """Apply ``saved`` (``bases()`` of the checkpoint) in the online and the target
        model, each checked to span the rebuilt layer's maps (``EquivariantLinear.adopt_bases``).
        Checkpoints written before the bases were saved have none: their layers keep the
        rebuilt bases, which the fingerprints then check."""
        if not saved:
            return
        for model in (self.model, self.loss.target_model):
            layers = dense_equivariant_layers(model)
            if layers.keys() != saved.keys():
                raise ValueError(f"the saved bases are for other layers (only saved: "
                                 f"{sorted(saved.keys() - layers.keys())[:3]}, only here: "
                                 f"{sorted(layers.keys() - saved.keys())[:3]})")
            for name, layer in layers.items():
                try:
                    layer.adopt_bases(saved[name])
                except ValueError as err:
                    raise ValueError(f"the checkpoint's bases for {name}: {err}") from None

    @torch.no_grad()
    def target_lag(self) -> float:
        """|online - target| / |online| over all model parameters: small and non-zero
        when the target tracks the online network, growing if it stopped moving."""
        online = list(self.model.parameters())
        target = list(self.loss.target_model.parameters())  # a deep copy: the same order
        # torch's total norm: the 2-norm of the per-tensor 2-norms (foreach kernels), the
        # same floating-point operations in the same order as before (tests/test_compat.py)
        gap = torch.nn.utils.get_total_norm([o - t for o, t in zip(online, target)], foreach=True)
        return float(gap / torch.nn.utils.get_total_norm(online, foreach=True))

    def state_dict(self) -> dict[str, Any]:
        networks = {k: v for k, v in self.loss.state_dict().items() if not rebuilt_with_networks(k)}
        return {"loss": networks, "bases": self.bases(),
                "basis_fingerprints": self.basis_fingerprints(),
                "model_optimizer": self.model_optimizer.state_dict(),
                "policy_optimizer": self.policy_optimizer.state_dict(),
                "generator": self.generator.get_state(), "updates": self.updates,
                **({} if self.augmentation is None
                   else {"augmentation_generator": self.augmentation.generator.get_state()})}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        missing, unexpected = self.loss.load_state_dict(state["loss"], strict=False)
        missing = [k for k in missing if not rebuilt_with_networks(k)]
        if missing or unexpected:
            raise ValueError(f"the saved networks do not fit this agent (missing "
                             f"{missing[:3]}, unexpected {unexpected[:3]})")
        self.adopt_bases(state.get("bases", {}))
        rebuilt = self.basis_fingerprints()
        for name, saved in state.get("basis_fingerprints", {}).items():
            now = rebuilt.get(name)
            if now is None or not torch.allclose(now, saved.to(now), rtol=1e-4, atol=1e-5):
                raise ValueError(f"escnn rebuilt a different basis (or sampling grid) for {name} "
                                 "than the one the checkpoint was trained with (another escnn "
                                 "version, or its disk cache filled on another CPU: "
                                 "docs/checkpoints.md)")
        self.model_optimizer.load_state_dict(state["model_optimizer"])
        self.policy_optimizer.load_state_dict(state["policy_optimizer"])
        self.generator.set_state(state["generator"])
        if self.augmentation is not None:
            self.augmentation.generator.set_state(state["augmentation_generator"])
        self.updates = state["updates"]
        self.planner.reset()
