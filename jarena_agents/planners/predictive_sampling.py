"""``predictive_sampling``: the sampling planner of MuJoCo MPC (Howell et al., 2022).

Per iteration: sample N - 1 plans ``clip(nominal + sigma * normal)`` around the nominal plan, score them
and the nominal itself by their summed model rewards over the horizon, and keep the best (the nominal on
ties) as the new nominal. Plans are zero-order (one action per agent step) rather than MuJoCo MPC's
splines. Noise ``sigma`` is a fraction of the action half-range.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from jarena_agents.planners.agent import PlannerConfig, make_planner
from jarena_agents.planners.model import Model
from jarena_agents.planners.sampling import action_bounds, half_range, rollout_returns, sample_plans
from jarena_agents.registry import register_agent


@dataclasses.dataclass(frozen=True)
class PredictiveSamplingConfig(PlannerConfig):
    """Exactly :class:`PlannerConfig`."""


def predictive_sampling_improve(model: Model, cfg: PredictiveSamplingConfig):
    """``(state, plan (H, *a), key) -> plan``: ``cfg.iterations`` rounds of keep-the-best."""
    low, high = action_bounds(model)
    std = cfg.noise * half_range(model)

    def improve(state, plan, key):
        def iteration(nominal, key):
            plans = sample_plans(key, nominal, std, cfg.samples, low, high)
            returns = rollout_returns(model, state, plans)
            return plans[jnp.argmax(returns)], None

        plan, _ = jax.lax.scan(iteration, plan, jax.random.split(key, cfg.iterations))
        return plan

    return improve


def make_predictive_sampling(config=None, arena=None, model=None):
    """The predictive sampling planner; see :mod:`jarena_agents.planners` for how it gets its arena."""
    return make_planner("predictive_sampling", PredictiveSamplingConfig, predictive_sampling_improve, config, arena,
                        model)


register_agent("predictive_sampling", make_predictive_sampling, tags=("planner", "arena_model"))
