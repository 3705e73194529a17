"""TD-MPC's MPPI planner, in a form that commutes with the symmetry group.

As in TD-MPC (Hansen et al. 2022): sample action sequences from a Gaussian and
from the policy, roll them out in latent space, score them by predicted
rewards plus a terminal Q, keep the elites, refit the Gaussian with
temperature-weighted statistics and momentum, warm-start from the previous
plan shifted by one step, and act with one elite sequence's first action.

Two changes make it equivariant when the networks are: the Gaussian's spread
is one standard deviation per action *field* (isotropic within a vector
field), and actions are kept in the action domain by ``project`` (scaling a
vector field back into the unit ball) rather than by clamping coordinates.
Then ``plan(g.s) = g.plan(s)`` whenever the noise is transformed by g as well;
``tests/test_planner.py`` checks exactly that. All randomness goes through a
``NoiseSource`` so that a test can replay it.
"""

from __future__ import annotations

import typing
from dataclasses import dataclass

import torch

from agents.nn.networks import project
from agents.options import OptionError, check, key, option
from agents.tdmpc.world_model import WorldModel


@dataclass
class PlannerConfig:
    """TD-MPC's planning hyperparameters (its defaults)."""

    KEY: typing.ClassVar[str] = "agent.planner"
    iterations: int = option(6, low=1)
    num_samples: int = option(512, low=1)
    num_elites: int = option(64, low=1)
    num_pi_trajs: int = option(25, low=0)  # TD-MPC's mixture_coef 0.05 of 512 samples
    temperature: float = option(0.5, low=0, low_open=True)
    momentum: float = option(0.1, low=0, high=1, high_open=True)
    max_std: float = option(2.0, low=0, low_open=True)
    discount: float = option(0.99, low=0, low_open=True)

    def __post_init__(self) -> None:
        check(self)
        if self.num_elites > self.num_samples + self.num_pi_trajs:
            raise OptionError(f"{key(PlannerConfig, 'num_elites')} ({self.num_elites}) exceeds the "
                              f"number of sampled trajectories ({self.num_samples + self.num_pi_trajs})")


class NoiseSource:
    """The planner's randomness: standard normal noise and a categorical choice."""

    def __init__(self, generator: torch.Generator) -> None:
        self.generator = generator

    def normal(self, shape: tuple[int, ...], like: torch.Tensor) -> torch.Tensor:
        return torch.randn(shape, generator=self.generator, dtype=like.dtype).to(like.device)

    def choice(self, probs: torch.Tensor) -> int:
        return int(torch.multinomial(probs.double().cpu(), 1, generator=self.generator))


class PlanValues(typing.NamedTuple):
    """What the last iteration of one plan valued its candidates at (predicted rewards
    plus terminal Q): the best Gaussian sample, and the best of the policy's proposals
    (None without them). A sample far above every proposal that then earns nothing
    is the planner trusting its model or Q where the policy does not go."""

    best_sampled: torch.Tensor
    best_proposed: torch.Tensor | None


class MPPIPlanner:
    """Plans one action at a time; keeps the previous plan for warm starts."""

    def __init__(self, model: WorldModel, config: PlannerConfig, policy_noise: float = 0.05) -> None:
        self.model, self.config = model, config
        # TD-MPC samples the policy's trajectories and the terminal action with its
        # fixed min_std (0.05), not with the scheduled exploration std.
        self.policy_noise = policy_noise
        fields = model.action_fields
        self.field_index = torch.repeat_interleave(
            torch.arange(len(fields)), torch.tensor([f.size for f in fields]))
        self.field_sizes = torch.tensor([float(f.size) for f in fields])
        self._prev_mean: torch.Tensor | None = None

    def reset(self) -> None:
        """Forget the previous plan (at the start of an episode)."""
        self._prev_mean = None

    def _per_field(self, values: torch.Tensor) -> torch.Tensor:
        """Sum over the coordinates of each field: [..., A] -> [..., n_fields]."""
        out = torch.zeros(*values.shape[:-1], len(self.field_sizes), dtype=values.dtype,
                          device=values.device)
        return out.index_add_(-1, self.field_index.to(values.device), values)

    @torch.no_grad()
    def estimate_value(self, z: torch.Tensor, actions: torch.Tensor,
                       noise: NoiseSource) -> torch.Tensor:
        """Discounted predicted rewards along ``actions`` [H, N, A] plus a terminal Q: [N, 1]."""
        value, discount = torch.zeros(z.shape[0], 1, dtype=z.dtype, device=z.device), 1.0
        for action in actions:
            value = value + discount * self.model.reward(z, action)
            z = self.model.next(z, action)
            discount *= self.config.discount
        terminal = self.model.pi(z, self.policy_noise,
                                 noise.normal((z.shape[0], self.model.action_dim), z))
        return value + discount * self.model.min_q(z, terminal)

    def plan(self, obs: torch.Tensor, *, horizon: int, min_std: float, explore: bool,
             noise: NoiseSource) -> torch.Tensor:
        """The action for observation ``obs`` [obs_dim]; ``min_std`` is TD-MPC's
        scheduled standard deviation (exploration noise and lower bound of the
        planner's spread)."""
        return self.plan_with_values(obs, horizon=horizon, min_std=min_std, explore=explore,
                                     noise=noise)[0]

    @torch.no_grad()
    def plan_with_values(self, obs: torch.Tensor, *, horizon: int, min_std: float,
                         explore: bool, noise: NoiseSource) -> tuple[torch.Tensor, PlanValues]:
        """:meth:`plan`'s action, and how its last iteration valued the candidates."""
        cfg, model = self.config, self.model
        fields, action_dim = model.action_fields, model.action_dim
        z0 = model.encode(obs.unsqueeze(0))
        index = self.field_index.to(z0.device)

        # Trajectories proposed by the policy.
        pi_actions = torch.empty(horizon, cfg.num_pi_trajs, action_dim, dtype=z0.dtype,
                                 device=z0.device)
        if cfg.num_pi_trajs > 0:
            z = z0.expand(cfg.num_pi_trajs, -1)
            for t in range(horizon):
                pi_actions[t] = model.pi(z, self.policy_noise, noise.normal(pi_actions[t].shape, z))
                z = model.next(z, pi_actions[t])

        # The Gaussian over action sequences, warm-started from the previous plan.
        mean = torch.zeros(horizon, action_dim, dtype=z0.dtype, device=z0.device)
        std = torch.full((horizon, len(fields)), cfg.max_std, dtype=z0.dtype, device=z0.device)
        if self._prev_mean is not None and len(self._prev_mean) > 1:
            shifted = self._prev_mean[1:horizon + 1]
            mean[:len(shifted)] = shifted

        z = z0.expand(cfg.num_samples + cfg.num_pi_trajs, -1)
        sizes = self.field_sizes.to(z0.device, z0.dtype)
        for _ in range(cfg.iterations):
            eps = noise.normal((horizon, cfg.num_samples, action_dim), z0)
            samples = project(mean.unsqueeze(1) + std[:, index].unsqueeze(1) * eps, fields)
            actions = torch.cat([samples, pi_actions], dim=1)
            value = self.estimate_value(z, actions, noise).squeeze(1)
            value = torch.nan_to_num(value, nan=-torch.inf)
            elite_value, elite_idx = torch.topk(value, cfg.num_elites)
            elite_actions = actions[:, elite_idx]
            score = torch.exp(cfg.temperature * (elite_value - elite_value.max()))
            score = score / score.sum()
            new_mean = torch.einsum("e,hea->ha", score, elite_actions)
            sq_dev = self._per_field((elite_actions - new_mean.unsqueeze(1)) ** 2)
            new_std = (torch.einsum("e,hef->hf", score, sq_dev) / sizes).sqrt()
            mean = cfg.momentum * mean + (1 - cfg.momentum) * new_mean
            std = new_std.clamp(min_std, cfg.max_std)

        chosen = elite_actions[:, noise.choice(score)]
        self._prev_mean = mean
        action = chosen[0]
        if explore:
            action = project(action + std[0, index] * noise.normal((action_dim,), action), fields)
        values = PlanValues(value[:cfg.num_samples].max(),
                            value[cfg.num_samples:].max() if cfg.num_pi_trajs > 0 else None)
        return action, values
