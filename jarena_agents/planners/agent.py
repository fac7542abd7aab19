"""The agent around a sampling planner: per-arena plans, warm start, new-episode resets, the model binding.

Each act plans for every one of the B arenas at once (``vmap``) from its privileged state, with a PRNG key
per arena: ``plan = improve(state, warm plan, key)``; the agent applies ``plan[0]`` and keeps the plan
shifted by one step (:func:`~jarena_agents.planners.sampling.shift_plan`) as the next warm start. A plan is
restarted from the no-op where the runner resets the agent (``reset(state, mask)``) and where
``info.step == 0`` (a new episode, also under runners that never call ``reset``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from jarena.core.agent import Agent
from jarena.core.arena import Arena, ArenaSpec
from jarena_agents.config import ConfigError, at_least, make_config, non_negative
from jarena_agents.planners.model import Model, arena_model
from jarena_agents.planners.sampling import WARM_STARTS, initial_plan, shift_plan, warm_start_fill

PyTree = Any
Improve = Callable[[PyTree, jax.Array, jax.Array], jax.Array]


@dataclasses.dataclass(frozen=True)
class PlannerConfig:
    """Settings every sampling planner has.

    Attributes:
      arena: build string of the arena the planner models (e.g. ``classic|domain:pendulum``); not needed
        when the factory is given ``arena=`` or ``model=``.
      samples: N, plans sampled per iteration (the current mean/nominal plan is always one of them).
      horizon: H, plan length in agent steps.
      iterations: sampling rounds per act.
      noise: standard deviation of the sampling noise, as a fraction of the action half-range
        ``(high - low) / 2``.
      warm_start: what the shifted plan is padded with: ``last`` (its last action) or ``no_op``.
    """

    arena: str = ""
    samples: int = at_least(1, default=256)
    horizon: int = at_least(1, default=30)
    iterations: int = at_least(1, default=1)
    noise: float = non_negative(0.5)
    warm_start: str = "last"


def check_config(cfg: PlannerConfig, agent: str) -> None:
    """Raises ``ConfigError`` for settings out of range (numeric ranges: the fields', checked by make_config)."""
    if cfg.warm_start not in WARM_STARTS:
        raise ConfigError(f"config key 'warm_start' of agent {agent!r} must be one of {list(WARM_STARTS)}, "
                          f"got {cfg.warm_start!r}")


def resolve_model(agent: str, cfg: PlannerConfig, arena: Arena | None = None, model: Model | None = None
                  ) -> tuple[Model, ArenaSpec | None, str]:
    """The model to plan with: ``model``, else the exact model of ``arena``, else of the arena built from
    ``cfg.arena``. Returns ``(model, spec of the arena it models or None, arena label for the config)``."""
    if model is not None:
        return model, None, cfg.arena or model.name
    if arena is None:
        if not cfg.arena:
            raise ConfigError(f"agent {agent!r} plans with the arena's own dynamics and needs that arena: pass "
                              f"config arena='<arena string>' (e.g. build_agent({agent!r}, "
                              f"{{'arena': 'classic|domain:pendulum'}})) or make the agent with arena=<Arena>")
        from jarena.building import build_arena

        arena = build_arena(cfg.arena)
    try:
        return arena_model(arena), arena.spec, arena.build_string or arena.name
    except ValueError as e:
        raise ConfigError(f"agent {agent!r} cannot plan in arena {arena.build_string or arena.name!r}: {e}") from None


@struct.dataclass
class PlannerState:
    """Per-arena warm start: ``plan`` float32 ``(B, H, *action_shape)``, the plan for the next step."""

    plan: jax.Array


def _where_arena(mask: jax.Array, a: jax.Array, b: jax.Array) -> jax.Array:
    return jnp.where(mask.reshape(mask.shape + (1,) * (a.ndim - mask.ndim)), a, b)


def planner_agent(name: str, cfg: PlannerConfig, model: Model, improve: Improve, spec: ArenaSpec | None = None,
                  config: dict | None = None) -> Agent:
    """An :class:`~jarena.core.agent.Agent` (``privileged=True``) that acts with ``improve``.

    Args:
      name: the agent's name.
      cfg: its settings (``horizon`` and ``warm_start`` are used here).
      model: the model ``improve`` plans with (its state is what ``act`` receives as ``privileged``).
      improve: ``(state, plan (H, *a), key) -> plan (H, *a)`` for one arena.
      spec: the spec of the arena the model is exact for; ``init`` refuses another arena's.
      config: what to record as ``Agent.config``.
    """
    template = initial_plan(model, cfg.horizon)
    action_dtype = model.action_spec.dtype

    def init(key, arena_spec, num_arenas):
        if spec is not None and arena_spec != spec:
            raise ValueError(f"agent {name!r} plans with the model of arena {model.name!r} "
                             f"(spec {spec}) but was initialised for arena {arena_spec.name!r} (spec {arena_spec})")
        return PlannerState(plan=jnp.broadcast_to(template, (num_arenas,) + template.shape))

    def reset(state, mask):
        return state.replace(plan=_where_arena(mask, template[None], state.plan))

    def plan_one(arena_state, plan, key):
        plan = improve(arena_state, plan, key)
        return plan[0], shift_plan(plan, warm_start_fill(plan, model, cfg.warm_start))

    def act(state, info, key, privileged):
        if privileged is None:
            raise ValueError(f"agent {name!r} needs the privileged arena state: run it with a runner that "
                             "passes arena.privileged(state) (agent.privileged is True)")
        model.check_state(privileged, batch_dims=1)
        plan = _where_arena(info.step == 0, template[None], state.plan)
        keys = jax.random.split(key, plan.shape[0])
        action, plan = jax.vmap(plan_one)(privileged, plan, keys)
        return action.astype(action_dtype), state.replace(plan=plan)

    return Agent(name=name, init=init, act=act, reset=reset, privileged=True, config=config)


def make_planner(name: str, config_cls: type, improve_factory: Callable[[Model, Any], Improve], config: Any,
                 arena: Arena | None, model: Model | None, check: Callable[[Any, str], None] | None = None
                 ) -> Agent:
    """Builds the planner ``name``: typed config, model binding, checks, the agent."""
    cfg = make_config(config_cls, config, agent=name)
    check_config(cfg, name)
    if check is not None:
        check(cfg, name)
    model, spec, label = resolve_model(name, cfg, arena, model)
    cfg = dataclasses.replace(cfg, arena=label)
    return planner_agent(name, cfg, model, improve_factory(model, cfg), spec, config=dataclasses.asdict(cfg))
