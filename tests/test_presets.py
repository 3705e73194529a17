"""An agent preset from Python (``agents.agent_config``) is the ``agent`` section that
``geomdp-train agent=<preset>`` composes, and its bad input is one line."""

from __future__ import annotations

import pytest
import yaml
from omegaconf import OmegaConf

from agents import TDMPCConfig, agent_config
from agents.options import OptionError
from agents.run.presets import CONFIG_DIR, compose_config


def test_the_cpu_preset_is_its_yaml_file():
    shipped = yaml.safe_load((CONFIG_DIR / "agent" / "tdmpc.yaml").read_text())
    assert agent_config() == TDMPCConfig.from_dict(shipped)
    cpu = agent_config("tdmpc")
    assert (cpu.networks.hidden_dim, cpu.networks.latent_dim, cpu.width_strategy) == (128, 32, "linear")
    assert cpu != TDMPCConfig()  # the dataclass's defaults are no preset


def test_the_paper_preset_overrides_the_cpu_preset_it_extends():
    paper = agent_config("tdmpc_paper")
    assert (paper.networks.hidden_dim, paper.networks.latent_dim, paper.width_strategy) == (512, 50, "sqrt")
    assert (paper.planner.num_samples, paper.batch_size, paper.replay.capacity) == (512, 512, 1_000_000)
    assert paper.loss == agent_config("tdmpc").loss  # what it does not set comes from tdmpc.yaml
    # the two files merged by hand, without Hydra: tdmpc.yaml, then tdmpc_paper.yaml over it
    own = OmegaConf.load(CONFIG_DIR / "agent" / "tdmpc_paper.yaml")
    assert list(own.pop("defaults")) == ["tdmpc", "_self_"]
    merged = OmegaConf.merge(OmegaConf.load(CONFIG_DIR / "agent" / "tdmpc.yaml"), own)
    assert paper == TDMPCConfig.from_dict(OmegaConf.to_container(merged))


def test_overrides_are_the_command_lines_without_agent():
    config = agent_config("tdmpc", "group=D8", "networks.hidden_dim=64", "planner.iterations=2")
    assert (config.group, config.networks.hidden_dim, config.planner.iterations) == ("D8", 64, 2)
    assert config.networks.latent_dim == 32  # the rest stays the preset's
    # Hydra's sigils stay in front: "++networks.hidden_dim=96" is "++agent.networks.hidden_dim=96"
    assert agent_config("tdmpc", "++networks.hidden_dim=96").networks.hidden_dim == 96
    hydra = compose_config(hydra=True)  # the resolvers its hydra section needs come with it
    assert OmegaConf.select(hydra, "hydra.launcher.n_jobs") >= 1


@pytest.mark.parametrize("args, message", [
    (("tdmpc_huge",), "unknown agent=tdmpc_huge; valid: tdmpc, tdmpc_paper"),
    (("tdmpc", "networks.width=3"), "unknown option agent.networks.width; valid: activation, "),
    (("tdmpc", "group"), "cannot parse an override: Error parsing override 'agent.group'"),
    (("tdmpc", "batch_size=0"), "agent.batch_size must be >= 1, got 0"),
    (("tdmpc", "group=Q7"), "agent.group='Q7'; valid: none, C<N>, D<N>"),
    (("tdmpc", "agent.group=D8"), "unknown option agent.agent; valid: allow_approximate, augment, "),
])
def test_bad_input_is_one_line_naming_the_valid_choices(args, message):
    with pytest.raises(OptionError) as error:
        agent_config(*args)
    assert str(error.value).startswith(message) and "\n" not in str(error.value)


def test_one_string_of_overrides_is_refused_not_split_into_characters():
    with pytest.raises(OptionError, match="a list of KEY=VALUE strings, got the string 'agent=tdmpc'"):
        compose_config("agent=tdmpc")
