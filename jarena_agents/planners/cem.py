"""``cem``: the cross-entropy method as a planner (Rubinstein, 1999; as in PETS/PlaNet).

Per iteration: sample N plans ``clip(mean + std * normal)`` (the mean itself included), score them by
their summed model rewards over the horizon, take the ``elite_fraction`` best (at least one) and refit
``mean`` and ``std`` (per step and action dimension) to them, blended with the previous values by
``smoothing`` (0: replace). ``std`` starts at ``noise`` and never falls below ``min_noise`` (fractions of
the action half-range); the mean is warm-started across steps, the std restarts at every act.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from jarena_agents.config import ConfigError
from jarena_agents.planners.agent import PlannerConfig, make_planner
from jarena_agents.planners.model import Model
from jarena_agents.planners.sampling import action_bounds, half_range, rollout_returns, sample_plans
from jarena_agents.registry import register_agent


@dataclasses.dataclass(frozen=True)
class CEMConfig(PlannerConfig):
    """:class:`PlannerConfig` plus ``elite_fraction`` (0, 1], ``min_noise`` >= 0, ``smoothing`` in [0, 1)."""

    iterations: int = 4
    elite_fraction: float = 0.1
    min_noise: float = 0.05
    smoothing: float = 0.0


def _check(cfg: CEMConfig, agent: str) -> None:
    if not 0 < cfg.elite_fraction <= 1:
        raise ConfigError(f"config key 'elite_fraction' of agent {agent!r} must be in (0, 1], "
                          f"got {cfg.elite_fraction}")
    if cfg.min_noise < 0:
        raise ConfigError(f"config key 'min_noise' of agent {agent!r} must be >= 0, got {cfg.min_noise}")
    if not 0 <= cfg.smoothing < 1:
        raise ConfigError(f"config key 'smoothing' of agent {agent!r} must be in [0, 1), got {cfg.smoothing}")


def num_elites(cfg: CEMConfig) -> int:
    """Elites kept per iteration: ``round(elite_fraction * samples)``, at least 1."""
    return max(1, round(cfg.elite_fraction * cfg.samples))


def cem_improve(model: Model, cfg: CEMConfig):
    """``(state, plan (H, *a), key) -> plan``: ``cfg.iterations`` CEM refits of the mean ``plan``."""
    low, high = action_bounds(model)
    scale = half_range(model)
    elites_n = num_elites(cfg)

    def improve(state, plan, key):
        def iteration(carry, key):
            mean, std = carry
            plans = sample_plans(key, mean, std, cfg.samples, low, high)
            returns = rollout_returns(model, state, plans)
            elites = plans[jax.lax.top_k(returns, elites_n)[1]]
            mean = cfg.smoothing * mean + (1 - cfg.smoothing) * elites.mean(0)
            std = cfg.smoothing * std + (1 - cfg.smoothing) * elites.std(0)
            return (mean, jnp.maximum(std, cfg.min_noise * scale)), None

        std = jnp.broadcast_to(cfg.noise * scale, plan.shape)
        (plan, _), _ = jax.lax.scan(iteration, (plan, std), jax.random.split(key, cfg.iterations))
        return plan

    return improve


def make_cem(config=None, arena=None, model=None):
    """The CEM planner; see :mod:`jarena_agents.planners` for how it gets its arena."""
    return make_planner("cem", CEMConfig, cem_improve, config, arena, model, _check)


register_agent("cem", make_cem, tags=("planner",))
