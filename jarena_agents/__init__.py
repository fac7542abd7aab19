"""jarena's agents: pure ``init / reset / act / update`` bundles, built by name.

    import jarena_agents
    agent = jarena_agents.build_agent("random")
"""

from jarena.core.agent import Agent
from jarena_agents import basic, oracles, planners  # noqa: F401  (registers the built-in agents)
from jarena_agents.bc import agent as _bc  # noqa: F401
from jarena_agents.config import ConfigError, make_config
from jarena_agents.diffusion import agent as _diffusion  # noqa: F401
from jarena_agents.dreamer import agent as _dreamer  # noqa: F401
from jarena_agents.noisy import noisy
from jarena_agents.planet import agent as _planet  # noqa: F401
from jarena_agents.ppo import agent as _ppo  # noqa: F401
from jarena_agents.registry import AGENTS, build_agent, list_agents, register_agent
from jarena_agents.sac import agent as _sac  # noqa: F401
from jarena_agents.trainable import TrainableAgent
from jarena_agents.transporter import agent as _transporter  # noqa: F401

__all__ = ["AGENTS", "Agent", "ConfigError", "build_agent", "list_agents", "make_config", "noisy", "register_agent",
           "TrainableAgent"]
