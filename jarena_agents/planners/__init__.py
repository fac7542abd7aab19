"""Sampling planners that roll an arena's own pure dynamics forward: ``mppi``, ``cem``, ``predictive_sampling``.

Every act, each planner optimises an open-loop plan of ``horizon`` actions for each of the B arenas (vmap
over arenas) from a copy of that arena's privileged state, applies the plan's first action and keeps the
rest, shifted by one step, as the next act's warm start (see :mod:`.agent`). Plans are scored by rolling a
:class:`~.model.Model` forward (``lax.scan`` over the horizon, ``vmap`` over N samples; :mod:`.sampling`).
All is pure and jittable, and deterministic given the act's key.

How a planner gets its arena. ``Agent.init`` sees only the arena's spec and ``act`` only its state, but a
planner needs the arena's ``step``. The planner therefore binds its model when it is built, from (first
given wins):

- ``model=``: any :class:`~.model.Model` (e.g. a learned one), ``make_mppi(config, model=model)``;
- ``arena=``: an :class:`~jarena.Arena` object, ``make_mppi(config, arena=arena)`` (also for arenas not
  built from a string);
- config key ``arena``: the arena's build string, ``build_agent("mppi", {"arena": "classic|domain:pendulum"})``.
  The shipped configs ``configs/<planner>/<arena-name>/default.yaml`` set it, so the CLI works as is:
  ``jarena evaluate mppi "classic|domain:pendulum"``; for other arenas pass ``--set arena=<arena string>``.

The model is the arena's own ``step`` with the arena's default params (fixed at build time), kept in the
agent's closures (no global state). ``init`` refuses an arena whose spec differs from the modelled one and
``act`` one whose state has another structure (other tools or task transforms); arenas that differ only in
params (e.g. ``time_limit``) are not told apart, so plan in the arena string you evaluate.
"""

from jarena_agents.planners import cem, mppi, predictive_sampling
from jarena_agents.planners.agent import PlannerConfig, PlannerState, planner_agent
from jarena_agents.planners.cem import CEMConfig, make_cem
from jarena_agents.planners.model import Model, arena_model
from jarena_agents.planners.mppi import MPPIConfig, make_mppi
from jarena_agents.planners.predictive_sampling import PredictiveSamplingConfig, make_predictive_sampling

__all__ = ["CEMConfig", "MPPIConfig", "Model", "PlannerConfig", "PlannerState", "PredictiveSamplingConfig",
           "arena_model", "cem", "make_cem", "make_mppi", "make_predictive_sampling", "mppi", "planner_agent",
           "predictive_sampling"]
