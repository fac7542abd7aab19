"""The Arena: dynamics + sensor + task + action tool, as pure ``reset`` and ``step`` functions."""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import jax
import jax.numpy as jnp

from jarena.core import episodes as episodes_lib
from jarena.core import faults
from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.resets import reset_strategy
from jarena.core.spec import Spec, spec_from_value
from jarena.core.task import Task
from jarena.core.tool import ActionTool
from jarena.core.tree import tree_where
from jarena.core.types import ArenaParams, ArenaState, Final, Info, KeyWords, Outcome, Transition

PyTree = Any


@dataclasses.dataclass(frozen=True)
class ArenaSpec:
    """What an agent needs to know of an arena before acting (static, hashable)."""

    observation: Spec
    action: Spec
    goal_dim: int = 0
    name: str = "arena"
    no_op: Any = dataclasses.field(default=None, compare=False, hash=False)


def _params_mismatch(expected: ArenaParams, params: Any, where: str) -> str:
    """Why ``params`` does not fit: not an ArenaParams, or which pieces differ from ``expected``'s."""
    if not isinstance(params, ArenaParams):
        return (f"{where}: params must be an ArenaParams (as arena.default_params() returns), got "
                f"{type(params).__name__}")
    lines = [f"{where}: params has the wrong structure (start from arena.default_params() and .replace leaves):"]
    for piece in ("dynamics", "sensor", "task", "tool"):
        want, got = (jax.tree_util.tree_structure(getattr(p, piece)) for p in (expected, params))
        if want != got:
            lines.append(f"  params.{piece}: expected a {type(getattr(expected, piece)).__name__} of structure "
                         f"{want}, got a {type(getattr(params, piece)).__name__} of structure {got}")
    return "\n".join(lines)


@dataclasses.dataclass(frozen=True)
class Arena:
    """An arena: pure functions over immutable pytrees.

    ``reset(key, params=None, episode=None) -> (state, info)`` and
    ``step(state, action, params=None) -> (state, info)`` work on one arena; ``jax.vmap`` them (or use
    :func:`jarena.batch_reset` / :func:`jarena.auto_reset`) for batches, ``jax.jit`` them as the caller.

    Attributes:
      dynamics: the physics (``Dynamics``), the first of the four pieces (see DESIGN.md).
      sensor: what the agent observes of the physics (``Sensor``).
      task: reward, termination and success of each step (``Task``).
      tool: turns the agent's action into control of the dynamics (``ActionTool``).
      name: a file-system friendly name (``classic-cartpole-balance``), used to find configs.
      build_string: the string that builds this arena, when it came from :func:`jarena.build_arena`.
      num_val_episodes: size of the fixed validation split.
      num_eval_episodes: size of the fixed evaluation split.
      auto_reset: how :func:`jarena.auto_reset` and :func:`jarena.batch_step` restart finished arenas:
        ``select`` (a fresh episode computed every step), ``lazy`` (fresh episodes computed only in steps
        where an arena finished) or ``repeat`` (each arena replays its first initial state, as Brax and
        Playground do); see :mod:`jarena.core.resets`.
    """

    dynamics: Dynamics
    sensor: Sensor
    task: Task
    tool: ActionTool = ActionTool(name="identity")
    name: str = "arena"
    build_string: str | None = None
    num_val_episodes: int = 20
    num_eval_episodes: int = 100
    auto_reset: str = "select"

    def __post_init__(self):
        reset_strategy(self.auto_reset)  # a clear error for an unknown name
        if self.dynamics.on_host != (self.auto_reset == "host"):
            raise ValueError(
                f"arena {self.name!r}: auto_reset 'host' is for dynamics whose simulator lives outside JAX (a "
                f"host arena, jarena.arenas.host), and such dynamics accept no other; dynamics "
                f"{self.dynamics.name!r} {'run' if self.dynamics.on_host else 'do not run'} on the host, got "
                f"auto_reset={self.auto_reset!r}")

    # ------------------------------------------------------------------ specs and params
    def default_params(self) -> ArenaParams:
        """The default params pytree; replace leaves (or vmap over them) to vary arenas."""
        return ArenaParams(dynamics=self.dynamics.default_params(), sensor=self.sensor.default_params(),
                           task=self.task.default_params(), tool=self.tool.default_params())

    @functools.cached_property
    def params_structure(self) -> jax.tree_util.PyTreeDef:
        """Pytree structure of ``default_params()``, which the params of ``reset`` and ``step`` must share."""
        return jax.tree_util.tree_structure(self.default_params())

    def _check_params(self, params: ArenaParams | None, where: str) -> ArenaParams:
        """``params`` (the defaults for ``None``) if it has the structure of ``default_params()``.

        Raises ``TypeError`` naming the piece that differs and what was expected. Only the (static)
        structure is compared, so this costs nothing under ``jit`` and works under ``vmap``.
        """
        if params is None:
            return self.default_params()
        if isinstance(params, ArenaParams) and jax.tree_util.tree_structure(params) == self.params_structure:
            return params
        raise TypeError(_params_mismatch(self.default_params(), params, f"{self.name}: {where}"))

    @functools.cached_property
    def action_spec(self) -> Spec:
        """Spec of the agent's action (after all action tools)."""
        return self.tool.spec(self.dynamics.control_spec)

    @functools.cached_property
    def reset_shapes(self) -> tuple[ArenaState, Info]:
        """``(state, info)`` of one arena's ``reset`` with the default params, as ``jax.ShapeDtypeStruct`` leaves.

        Traced once (an MJX arena's reset takes seconds to trace) and shared by the observation spec, the goal
        size, the runners' fit check (:func:`jarena.core.agent.check_agent_fits`) and planners' arena models.
        """
        return jax.eval_shape(lambda: self.reset(jax.random.key(0)))

    @functools.cached_property
    def observation_spec(self) -> Spec:
        """Spec of ``info.observation``."""
        if self.sensor.spec is not None:
            return self.sensor.spec
        return spec_from_value(self.reset_shapes[1].observation)

    @functools.cached_property
    def goal_dim(self) -> int:
        return int(self.reset_shapes[1].goal.shape[0])

    @property
    def spec(self) -> ArenaSpec:
        return ArenaSpec(observation=self.observation_spec, action=self.action_spec, goal_dim=self.goal_dim,
                         name=self.name, no_op=jax.device_get(self.no_op()))

    @functools.cached_property
    def max_episode_steps(self) -> int | None:
        """Static upper bound on agent steps per episode (from the task's horizon), or ``None``."""
        if self.task.horizon is None:
            return None
        return math.ceil(self.task.horizon / max(self.tool.substeps, 1))

    def no_op(self) -> PyTree:
        """An action that applies no actuation (in the agent's action space)."""
        return self.tool.no_op(self.dynamics.no_op_control(), self.dynamics.control_spec)

    def sample_action(self, key: jax.Array) -> PyTree:
        """A uniformly random valid action."""
        return self.action_spec.sample(key)

    def episodes(self, split: str) -> range:
        """Episode ids of ``split`` (``train``: the sampling range; ``val``/``eval``: fixed lists)."""
        return episodes_lib.split_episodes(split, self.num_val_episodes, self.num_eval_episodes)

    def privileged(self, state: ArenaState) -> ArenaState:
        """The full simulator state, for oracle and planning agents (never part of observations).

        States are immutable, so this is a safe copy: planners may roll it forward with ``step``. A host
        arena's state is a handle on a simulator outside JAX, so it has none to give (a ``TypeError``).
        """
        if self.dynamics.on_host:
            raise TypeError(f"arena {self.name!r} runs its simulator on the host (outside JAX): its state cannot "
                            "be copied or rolled forward, so agents that read privileged states (planners over "
                            "the true dynamics, oracles) cannot run on it; agents that act on observations can")
        return state

    # ------------------------------------------------------------------ reset and step
    def reset(self, key: jax.Array | None = None, params: ArenaParams | None = None,
              episode: jax.Array | int | None = None) -> tuple[ArenaState, Info]:
        """Starts an episode.

        Args:
          key: PRNG key. Without ``episode`` it draws a training episode id; it also seeds the episodes
            that follow under auto-reset. May be ``None`` when ``episode`` is given.
          params: arena params (``default_params()`` when ``None``); an :class:`ArenaParams` of the
            structure of ``default_params()`` (else a ``TypeError``).
          episode: int32 episode id; the episode is a pure function of the arena, params and this id.
            A concrete id outside ``[0, 2^31)`` raises ``ValueError``; under ``jit`` ids are not checked.

        Returns:
          ``(state, info)`` with ``info.step == 0`` and zero reward.
        """
        params = self._check_params(params, "reset")
        episodes_lib.check_episode_ids(episode, f"{self.name}: reset")
        if episode is None:
            if key is None:
                raise ValueError("reset() needs a key, an episode id, or both")
            episode = episodes_lib.episode_of_key(key)
        else:
            episode = jnp.asarray(episode, jnp.int32)
        physics = self.dynamics.init(episodes_lib.piece_key(episode, 0), params.dynamics)
        return self.begin_episode(physics, key, episode, params)

    def begin_episode(self, physics: PyTree, key: jax.Array | None, episode: jax.Array, params: ArenaParams
                      ) -> tuple[ArenaState, Info]:
        """What :meth:`reset` does after ``dynamics.init``: episode ``episode`` (int32) from the dynamics'
        initial ``physics`` (the task places it, the task and tool start, the sensor observes). ``key`` (or
        ``None``) seeds the episodes after this one under auto-reset, as in :meth:`reset`."""
        key_task, key_tool = episodes_lib.piece_key(episode, 1), episodes_lib.piece_key(episode, 2)
        # The key that seeds the episodes after this one under auto-reset.
        rng = episodes_lib.piece_key(episode, 3) if key is None else jax.random.fold_in(key, 1)
        physics = self.task.initialize(episodes_lib.piece_key(episode, 4), physics, params.dynamics, params.task)
        if self.dynamics.after_reset is not None:
            physics = self.dynamics.after_reset(physics, params.dynamics)
        outcome, task_state = self.task.reset(key_task, physics, Outcome.empty(), params.task)
        tool_state = self.tool.reset(key_tool, params.tool, self.dynamics.control_spec)
        state = ArenaState(physics=physics, task=task_state, tool=tool_state, step=jnp.zeros((), jnp.int32),
                           episode=episode, rng=KeyWords.pack(rng))
        state, observation = self._observe(state, params, first=True)
        info = self._info(state, observation, outcome, params)
        if reset_strategy(self.auto_reset).keeps_start:
            state = state.replace(start=(state, info))
        return state, info

    def step(self, state: ArenaState, action: PyTree, params: ArenaParams | None = None
             ) -> tuple[ArenaState, Info]:
        """Applies ``action`` and returns the new state and info.

        The action's shape and dtype are validated statically against ``action_spec`` (a clear
        ``SpecError`` otherwise); its values too when concrete (given eagerly, not traced): a ``Discrete``
        value out of range or a non-finite float is a ``SpecError``. Floats outside a ``Box``'s bounds are
        not: dynamics clip out-of-range controls themselves, as Gymnasium's do. ``params`` is checked as
        in :meth:`reset`.

        Faults (traced, so under ``jit`` and ``vmap`` too; ``info.fault``, see :mod:`jarena.core.faults`):

        - an action with a non-finite float or an integer out of range (``Discrete(n)`` given ``-1`` or
          ``n``) is ``INVALID_ACTION``: the step runs ``no_op()`` in its place (never an out-of-bounds
          index or a huge force), and ends the episode. Floats outside a ``Box``'s bounds are valid.
        - a physics state (``Dynamics.is_finite``), observation or reward with a NaN or an infinity after
          the step is ``NONFINITE_STATE``.

        A faulted step is ``terminated`` (no bootstrapping from it), its reward is 0 and ``success`` false,
        and the non-finite entries of its observation (``info.observation`` and
        ``info.final.observation``), ``reward_terms`` and ``metrics`` are 0, so a learner's value of the final
        observation and every mean a report takes are finite.
        """
        params = self._check_params(params, "step")
        action = self.action_spec.validate(action, "action")

        def low_level_step(carry, control):
            physics, task_state = carry
            next_physics = self.dynamics.step(physics, control, params.dynamics)
            outcome, task_state = self.task.update(task_state, Outcome.empty(),
                                                   Transition(physics, control, next_physics, params.dynamics),
                                                   params.task)
            return (next_physics, task_state), outcome

        # An invalid action is never simulated: the no-op runs in its place (and the step faults).
        invalid = ~faults.valid_action(self.action_spec, action)
        no_op = jax.tree_util.tree_map(lambda n, a: jnp.asarray(n, a.dtype), self.no_op(), action)
        action = tree_where(invalid, no_op, action)
        (physics, task_state), outcome, tool_state = self.tool.step(
            state.tool, action, (state.physics, state.task), low_level_step, params.tool,
            self.dynamics.control_spec)
        state = state.replace(physics=physics, task=task_state, tool=tool_state, step=state.step + 1)
        state, observation = self._observe(state, params, first=False)
        return state, self._info(state, observation, outcome, params, invalid)

    def _observe(self, state: ArenaState, params: ArenaParams, first: bool) -> tuple[ArenaState, PyTree]:
        """The observation the agent sees of ``state``, and ``state`` with the sensor's memory updated."""
        observation = self.sensor.observe(state.physics, params.sensor)
        memory = self.sensor.memory
        if memory is None:
            return state, observation
        remembered, observation = memory.start(observation) if first else memory.advance(state.sensor, observation)
        return state.replace(sensor=remembered), observation

    def _info(self, state: ArenaState, observation: PyTree, outcome: Outcome, params: ArenaParams,
              invalid_action: jax.Array | None = None) -> Info:
        """The info of ``state`` with ``observation``; after a step (``invalid_action`` given) with its fault
        applied."""
        reward = jnp.asarray(outcome.reward, jnp.float32)
        terminated = jnp.asarray(outcome.terminated, bool)
        success = jnp.asarray(outcome.success, bool)
        fault = jnp.zeros((), jnp.int32)
        reward_terms, metrics = outcome.reward_terms, outcome.metrics
        if invalid_action is not None:
            finite = self.dynamics.is_finite(state.physics) & faults.all_finite(observation) & jnp.isfinite(reward)
            fault = faults.code(invalid_action, ~finite)
            faulted = fault != 0
            observation = faults.zero_nonfinite(observation)
            reward_terms, metrics = faults.zero_nonfinite((reward_terms, metrics))
            reward = jnp.where(faulted, jnp.zeros((), jnp.float32), reward)
            terminated = terminated | faulted
            success = success & ~faulted
        return Info(observation=observation,
                    reward=reward,
                    terminated=terminated,
                    truncated=jnp.asarray(outcome.truncated, bool),
                    success=success, goal=outcome.goal,
                    step=state.step, episode=state.episode, reward_terms=reward_terms,
                    metrics=metrics,
                    final=Final(observation=observation, goal=outcome.goal, step=state.step, episode=state.episode),
                    fault=fault)
