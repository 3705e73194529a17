"""The options validator (agents/options.py): one rule for types, ranges, choices,
unknown and missing keys, nested sections, and the key each message names."""

import pytest

from agents.nn.networks import Architecture, NetworkConfig, build_networks
from agents.options import OptionError, from_dict
from agents.run.config import EnvOptions, RunOptions
from agents.tdmpc.agent import TDMPCConfig
from agents.tdmpc.replay import ReplayConfig


@pytest.mark.parametrize("build, message", [
    # the key is the declaring dataclass's KEY, whether built from a config or in Python
    (lambda: Architecture(latent_dim=0), "agent.networks.latent_dim must be >= 1, got 0"),
    (lambda: NetworkConfig(width_strategy="cube"), "agent.width_strategy='cube'; valid: sqrt, linear"),
    (lambda: TDMPCConfig.from_dict({"networks": {"latent_dim": 0}}),
     "agent.networks.latent_dim must be >= 1, got 0"),
    (lambda: ReplayConfig(beta=2.0), "agent.replay.beta must be in [0, 1], got 2.0"),
    (lambda: TDMPCConfig(tau=0.0), "agent.tau must be in (0, 1], got 0.0"),
    (lambda: TDMPCConfig.from_dict({"lr": True}), "agent.lr must be a number, got True"),
    (lambda: TDMPCConfig.from_dict({"horizon": 2.0}), "agent.horizon must be an integer, got 2.0"),
    (lambda: TDMPCConfig.from_dict({"networks": {"max_frequency": "two"}}),
     "agent.networks.max_frequency must be an integer, got 'two'"),
    (lambda: TDMPCConfig.from_dict({"planner": {"samples": 3}}),
     "unknown option agent.planner.samples; valid: discount,"),
    (lambda: TDMPCConfig.from_dict({"planner": 3}), "agent.planner must be a mapping, got 3"),
    (lambda: TDMPCConfig(networks={"hidden_dim": 3}),
     "agent.networks must be of type Architecture, got {'hidden_dim': 3}"),
    (lambda: TDMPCConfig.from_dict({"group": "D8", "equivariant": {"transition": False}}),
     "an equivariant Q or policy needs an equivariant latent state"),
    (lambda: RunOptions.from_config({"env": {"action_repeat": 2}}), "env.id is required"),
    (lambda: RunOptions.from_config({"env": {"id": "x"}, "resolved": {}}),
     "unknown option 'resolved'; valid: agent, device, env, logger, seed, train"),
    (lambda: RunOptions.from_config({"env": {"id": "x"}, "logger": {"tensorboard": "maybe"}}),
     "logger.tensorboard='maybe'; valid: true, false, auto"),
])
def test_bad_options_are_one_line_naming_their_key(build, message):
    with pytest.raises(OptionError) as err:
        build()
    assert message in str(err.value) and "\n" not in str(err.value)


def test_good_options_build_and_keep_their_values():
    cfg = TDMPCConfig.from_dict({"group": "none", "networks": {"hidden_dim": 64}, "lr": 1,
                                 "equivariant": {"q": False}})
    assert cfg.group is None and cfg.networks.hidden_dim == 64 and cfg.lr == 1
    assert build_networks(cfg, None, 4, 2).config is cfg  # the agent's config is the networks' config
    env = EnvOptions.from_section({"id": "GeoMDP/Reacher-v0", "name": "reacher",
                                   "action_repeat": 4, "difficulty": "hard"})
    assert env.kwargs == {"difficulty": "hard"} and env.action_repeat == 4
    options = RunOptions.from_config({"env": {"id": "x"}, "logger": {"tensorboard": False}})
    assert options.logger.tensorboard is False and options.resolved["env"] == {"id": "x"}
    assert from_dict(RunOptions, {"env": {"id": "x"}}).checkpoint_options()["env.id"] == "x"


def test_a_run_directorys_options_are_read_from_its_config(tmp_path):
    """``RunOptions.from_run_dir``: what the run recorded, or one line naming the missing file."""
    from omegaconf import OmegaConf

    from agents.run.presets import compose_config

    with pytest.raises(OptionError, match=r"config.yaml: no such file") as err:
        RunOptions.from_run_dir(tmp_path)
    assert "\n" not in str(err.value)
    resolved = OmegaConf.to_container(compose_config(["env=reacher", "seed=4", "agent.group=D8"]),
                                      resolve=True)
    OmegaConf.save(OmegaConf.create(resolved), tmp_path / "config.yaml")
    options = RunOptions.from_run_dir(tmp_path)
    assert options.seed == 4 and options.env.name == "reacher" and options.agent.group == "D8"
    assert options.resolved == resolved
