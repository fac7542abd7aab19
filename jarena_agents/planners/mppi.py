"""``mppi``: model predictive path integral control (Williams et al., 2017), sampling form.

Per iteration: sample N plans ``clip(mean + sigma * normal)`` around the mean plan (the mean itself
included), score each by its summed model rewards over the horizon (``R_i``), and replace the mean by
the exponentially weighted average ``sum_i w_i plan_i`` with ``w = softmax(R / temperature)``. A low
temperature approaches the best sample, a high one the plain average. Temperature is in reward units
(summed over the horizon); noise ``sigma`` is a fraction of the action half-range.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from jarena_agents.config import positive
from jarena_agents.planners.agent import PlannerConfig, make_planner
from jarena_agents.planners.model import Model
from jarena_agents.planners.sampling import action_bounds, half_range, rollout_returns, sample_plans
from jarena_agents.registry import register_agent


@dataclasses.dataclass(frozen=True)
class MPPIConfig(PlannerConfig):
    """:class:`PlannerConfig` plus the MPPI temperature.

    Attributes:
      temperature: lambda > 0 of the weights ``softmax(R / temperature)``, in reward units (returns summed over
        the horizon): low approaches the best sample, high the plain average of the samples.
    """

    temperature: float = positive(1.0)


def mppi_improve(model: Model, cfg: MPPIConfig):
    """``(state, plan (H, *a), key) -> plan``: ``cfg.iterations`` MPPI updates of ``plan`` from ``state``."""
    low, high = action_bounds(model)
    std = cfg.noise * half_range(model)

    def improve(state, plan, key):
        def iteration(mean, key):
            plans = sample_plans(key, mean, std, cfg.samples, low, high)
            returns = rollout_returns(model, state, plans)
            weights = jax.nn.softmax(returns / cfg.temperature)
            return jnp.tensordot(weights, plans, axes=1), None

        plan, _ = jax.lax.scan(iteration, plan, jax.random.split(key, cfg.iterations))
        return plan

    return improve


def make_mppi(config=None, arena=None, model=None):
    """The MPPI planner; see :mod:`jarena_agents.planners` for how it gets its arena."""
    return make_planner("mppi", MPPIConfig, mppi_improve, config, arena, model)


register_agent("mppi", make_mppi, tags=("planner", "arena_model"))
