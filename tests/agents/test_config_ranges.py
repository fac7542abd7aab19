"""Agent configs refuse out-of-range values, and unknown agent names are an error."""

import dataclasses
import importlib
import math
import pkgutil
import re
import typing

import pytest

import jarena
import jarena_agents
from jarena.building.registry import RegistryError
from jarena_agents.config import ConfigError, Range, make_config


def config_classes() -> list[type]:
    """Every ``*Config`` dataclass defined in a jarena_agents module."""
    found = {}
    for info in pkgutil.walk_packages(jarena_agents.__path__, "jarena_agents."):
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if (name.endswith("Config") and dataclasses.is_dataclass(value) and isinstance(value, type)
                    and value.__module__ == module.__name__):
                found[name] = value
    return [found[name] for name in sorted(found)]


def numeric(hint) -> bool:
    kinds = typing.get_args(hint) or (hint,)
    return any(kind in (int, float) for kind in kinds)


def test_every_numeric_config_key_declares_its_range_and_the_defaults_pass():
    classes = config_classes()
    assert {"PPOConfig", "SACConfig", "BCConfig", "PlannerConfig", "CEMConfig", "MPPIConfig", "RandomConfig",
            "CartPoleOracleConfig", "DmcReacherOracleConfig"} <= {c.__name__ for c in classes}
    for cls in classes:
        make_config(cls, {})  # the defaults are in range
        hints = typing.get_type_hints(cls)
        for field in dataclasses.fields(cls):
            if numeric(hints[field.name]):  # feedback gains too: they declare unbounded()
                assert isinstance(field.metadata.get("range"), Range), f"{cls.__name__}.{field.name} has no range"


@pytest.mark.parametrize("agent, key, value, valid", [
    ("ppo", "learning_rate", -1, "> 0"),
    ("ppo", "learning_rate", float("nan"), "> 0"),
    ("ppo", "num_arenas", 0, ">= 1"),
    ("ppo", "discount", 0.0, r"in \(0, 1\]"),
    ("ppo", "discount", 1.5, r"in \(0, 1\]"),
    ("ppo", "gae_lambda", 1.1, r"in \[0, 1\]"),
    ("ppo", "clip_epsilon", 0.0, "> 0"),
    ("ppo", "entropy_coef", -0.01, ">= 0"),
    ("ppo", "max_grad_norm", 0.0, "> 0"),
    ("ppo", "unroll_length", 0, ">= 1"),
    ("sac", "tau", 0.0, r"in \(0, 1\]"),
    ("sac", "learning_starts", -1, ">= 0"),
    ("sac", "critic_lr", 0.0, "> 0"),
    ("bc", "batch_size", 0, ">= 1"),
    ("bc", "nll_beta", 2.0, r"in \[0, 1\]"),
    ("cem", "iterations", 0, ">= 1"),
    ("cem", "smoothing", 1.0, r"in \[0, 1\)"),
    ("mppi", "noise", -0.5, ">= 0"),
    ("oracle_cartpole", "k_theta", float("nan"), r"a number \(not NaN\)"),
    ("oracle_dmc_cartpole", "r", 0.0, "> 0"),
    ("oracle_dmc_reacher", "natural_frequency", -30.0, "> 0"),
    ("oracle_pendulum", "capture_angle", 4.0, r"in \[0, 3.14159\]"),
])
def test_out_of_range_values_name_the_key_the_value_and_the_range(agent, key, value, valid):
    config = {key: value} if agent not in ("cem", "mppi") else {"arena": "classic|domain:pendulum", key: value}
    with pytest.raises(ConfigError, match=f"config key '{key}' of agent '{agent}' must be {valid}, got "
                                          f"{re.escape(repr(value))}"):
        jarena_agents.build_agent(agent, config)


def test_null_skips_the_range_of_optional_keys():
    assert jarena_agents.build_agent("ppo", {"max_grad_norm": None, "unroll_length": None}).config[
        "max_grad_norm"] is None
    assert 0 not in Range(0, open_low=True) and math.inf in Range(0) and str(Range(high=1, open_high=True)) == "< 1"
    assert jarena_agents.build_agent("oracle_cartpole", {"k_theta": -2.0}).config["k_theta"] == -2.0  # gains: any sign


# ---------------------------------------------------------------------------------------------- agent names
def test_retrieve_config_of_an_unknown_agent_is_the_registry_error():
    arena = jarena.build_arena("classic|domain:cartpole")
    with pytest.raises(RegistryError) as from_configs:
        jarena.retrieve_config("nosuch", arena)
    with pytest.raises(RegistryError) as from_registry:
        jarena_agents.build_agent("nosuch")
    assert str(from_configs.value) == str(from_registry.value)
    assert str(from_configs.value).startswith("unknown agent 'nosuch'; valid choices: ")
    with pytest.raises(KeyError, match="did you mean 'oracle_cartpole'"):
        jarena.retrieve_config("oracle_cartpol", arena)


def test_retrieve_config_still_serves_registered_agents_without_configs_and_agent_objects():
    arena = jarena.build_arena("classic|domain:cartpole")
    assert "random" in jarena_agents.AGENTS and jarena.retrieve_config("random", arena) == {}
    assert jarena.retrieve_config(jarena_agents.build_agent("random"), arena) == {}
    assert jarena.retrieve_config("ppo", arena)["num_arenas"] >= 1  # a tuned config


def test_cli_gives_one_clear_error_for_an_unknown_agent(capsys):
    from jarena.cli import main

    assert main(["evaluate", "nosuch", "classic|domain:cartpole"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("jarena: error: unknown agent 'nosuch'; valid choices: ")
