"""The shipped configs (``configs/``: tasks, agent presets, experiments) composed as
``geomdp-train`` composes them, with its overrides and its one-line errors; and an agent
preset as the agent's config, for Python: ``agent_config("tdmpc", "group=D8")`` is the
``agent`` section of ``geomdp-train agent=tdmpc agent.group=D8``."""

from __future__ import annotations

import hashlib
import os
from collections.abc import Sequence
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.errors import ConfigCompositionException, MissingConfigException, OverrideParseException
from omegaconf import DictConfig, OmegaConf

from agents.options import OptionError, unknown
from agents.tdmpc.agent import TDMPCConfig


def _config_dir() -> Path:
    """The configs shipped inside an installed package (``agents/configs``, put there
    by the wheel), else the checkout's top-level ``configs/``."""
    packaged = Path(__file__).resolve().parents[1] / "configs"
    return packaged if packaged.is_dir() else Path(__file__).resolve().parents[2] / "configs"


CONFIG_DIR = _config_dir()
MAX_DIRNAME = 120  # a multirun job's directory name, at most


# Hydra's directory names and resolvers (configs/train.yaml's ``hydra`` section uses them)
def sweep_dirname(overrides: str) -> str:
    """A multirun job's directory name: its overrides (``a.b=1,seed=2``), or, when that is
    too long for the filesystem, the swept values kept readable: keys shortened to their
    last part, then values only (but ``seed=``, which comes first), and a hash of the whole list so that
    two jobs never share a directory."""
    name = overrides.replace("/", "-") or "default"
    if len(name) <= MAX_DIRNAME:
        return name
    digest = hashlib.sha1(name.encode()).hexdigest()[:8]
    pairs = [item.partition("=") for item in name.split(",")]
    pairs.sort(key=lambda p: p[0] != "seed")  # stable: seed first, the rest as Hydra sorted them
    room = MAX_DIRNAME - len(digest) - 1
    for short in (",".join(f"{k.rsplit('.', 1)[-1]}={v}" for k, _, v in pairs),
                  ",".join(f"{k}={v}" if k == "seed" else v for k, _, v in pairs)):
        if len(short) <= room:
            return f"{short}_{digest}"
    width = max(1, room // len(pairs) - 1)  # every value cut to the same width
    return f"{','.join(v[:width] for _, _, v in pairs)[:room]}_{digest}"


def usable_cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


OmegaConf.register_new_resolver("geomdp_dirname", sweep_dirname, replace=True)
OmegaConf.register_new_resolver("geomdp_cores", usable_cores, replace=True)


def _compose(overrides: list[str], hydra: bool) -> DictConfig:
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose("train", overrides=overrides, return_hydra_config=hydra)


def compose_config(overrides: Sequence[str] = (), hydra: bool = False) -> DictConfig:
    """The training config with ``geomdp-train``'s overrides (``hydra``: with Hydra's own
    section). What Hydra refuses in a many-line report (an unknown key, an unknown config
    group option, an unparsable override) is an ``OptionError`` of one line naming the
    valid choices."""
    if isinstance(overrides, str):
        raise OptionError(f"overrides must be a list of KEY=VALUE strings, got the string {overrides!r}")
    overrides = list(overrides)
    try:
        return _compose(overrides, hydra)
    except MissingConfigException as err:
        group, _, name = (err.missing_cfg_file or "").rpartition("/")
        valid = ", ".join(err.options or []) or "none found"
        raise OptionError(f"unknown {group or 'config'}={name}; valid: {valid}") from None
    except OverrideParseException as err:
        raise OptionError(f"cannot parse an override: {str(err).splitlines()[0]}") from None
    except ConfigCompositionException as err:
        bad = getattr(err.__cause__, "full_key", None)
        if not bad:
            raise OptionError(" ".join(str(err).split())) from None
        parent, _, _ = str(bad).rpartition(".")
        rest = [o for o in overrides if not o.lstrip("+~").startswith((f"{bad}=", f"{bad}."))]
        try:
            base = _compose(rest, hydra)
            node = OmegaConf.select(base, parent) if parent else base
        except (ConfigCompositionException, MissingConfigException, OverrideParseException):
            node = None
        valid = [k for k in node.keys() if k != "hydra"] if isinstance(node, DictConfig) else []
        raise unknown(str(bad), valid) from None


def agent_config(preset: str = "tdmpc", *overrides: str) -> TDMPCConfig:
    """An agent preset of ``configs/agent/`` (``tdmpc``: the CPU preset; ``tdmpc_paper``:
    TD-MPC's sizes) as a ``TDMPCConfig``, with ``geomdp-train``'s ``agent.*`` overrides
    written without their ``agent.`` (``"group=D8"``, ``"networks.hidden_dim=64"``, Hydra's
    ``+``/``~`` in front as usual). Bad input is an ``OptionError`` of one line naming the
    valid choices."""
    def under_agent(override: str) -> str:
        body = override.lstrip("+~")
        return f"{override[:len(override) - len(body)]}agent.{body}"

    cfg = compose_config([f"agent={preset}", *map(under_agent, overrides)])
    return TDMPCConfig.from_dict(OmegaConf.to_container(cfg.agent, resolve=True))
