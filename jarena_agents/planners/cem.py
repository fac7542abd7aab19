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

from jarena_agents.config import at_least, in_unit_interval, non_negative
from jarena_agents.planners.agent import PlannerConfig, make_planner
from jarena_agents.planners.model import Model
from jarena_agents.planners.sampling import action_bounds, half_range, rollout_returns, sample_plans
from jarena_agents.registry import register_agent


@dataclasses.dataclass(frozen=True)
class CEMConfig(PlannerConfig):
    """:class:`PlannerConfig` plus the elites and the refit.

    Attributes:
      elite_fraction: share of the ``samples`` kept as elites, in (0, 1]: ``round(elite_fraction * samples)``
        plans with the highest returns, at least one.
      min_noise: floor of the sampling standard deviation after each refit, as a fraction of the action
        half-range (>= 0).
      smoothing: weight of the previous mean and standard deviation in each refit, in [0, 1):
        ``new = smoothing * old + (1 - smoothing) * elite statistic`` (0: replaced by the elites').
    """

    iterations: int = at_least(1, default=4)
    elite_fraction: float = in_unit_interval(0.1, open_low=True)
    min_noise: float = non_negative(0.05)
    smoothing: float = in_unit_interval(0.0, open_high=True)


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
    return make_planner("cem", CEMConfig, cem_improve, config, arena, model)


register_agent("cem", make_cem, tags=("planner", "arena_model"))
