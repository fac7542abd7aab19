"""Tasks: composable transforms that turn physics transitions into rewards, goals and terminations.

A :class:`Task` is a frozen bundle of pure functions, in the manner of optax's
``GradientTransformation``. Each task owns one slot of state and one slot of params and threads an
:class:`~jarena.core.types.Outcome` through: a base task (e.g. cartpole balance) fills reward and
termination, later transforms in a :func:`chain` adjust them (``time_limit``, ``reward_scale``...).

Tasks run once per *low-level* dynamics step, so with an action-repeat tool rewards accumulate over
the repeated steps and a time limit counts physical time, as in dm_control.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax

from jarena.core.types import Outcome, Transition

PyTree = Any


def _no_params() -> tuple:
    return ()


def _no_state_reset(key, physics, outcome, params):
    return outcome, ()


def _keep_physics(key, physics, dynamics_params, params):
    return physics


@dataclasses.dataclass(frozen=True)
class Task:
    """A task transform.

    Attributes:
      update: ``(state, outcome, transition, params) -> (outcome, state)``; runs after every dynamics
        step with the outcome produced so far by earlier transforms in the chain.
      reset: ``(key, physics, outcome, params) -> (outcome, state)``; runs at episode start on the
        initial physics; must produce an outcome with the same structure as ``update`` (same reward
        terms and metrics, goal of the same shape).
      default_params: ``() -> params`` pytree.
      horizon: static upper bound on the number of dynamics steps in an episode (``None``: unbounded);
        runners use it to size their loops.
      name: a short name for messages.
      initialize: ``(key, physics, dynamics_params, params) -> physics``; places the episode's initial
        state (dm_control's ``initialize_episode``: a swing-up task starts the pole hanging down, a reach
        task places its target). Runs on the dynamics' initial physics, before ``reset``; the default
        keeps the physics as the dynamics made it.
      has_success: whether the task defines a success criterion (sets ``outcome.success``); a chain has one
        when any of its tasks does. Without one (the suite's walker or cheetah), results report the success
        rate as "n/a" rather than 0%.
    """

    update: Callable[[PyTree, Outcome, Transition, PyTree], tuple[Outcome, PyTree]]
    reset: Callable[[jax.Array, PyTree, Outcome, PyTree], tuple[Outcome, PyTree]] = _no_state_reset
    default_params: Callable[[], PyTree] = _no_params
    horizon: int | None = None
    name: str = "task"
    initialize: Callable[[jax.Array, PyTree, PyTree, PyTree], PyTree] = _keep_physics
    has_success: bool = False

    @staticmethod
    def chain(*tasks: Task) -> Task:
        """Composes tasks left to right; state and params are tuples with one slot per task."""
        for t in tasks:
            if not isinstance(t, Task):
                raise TypeError(f"chain of tasks got {t!r}, which is not a Task")

        def reset(key, physics, outcome, params):
            keys = [jax.random.fold_in(key, i) for i in range(len(tasks))]
            states = []
            for task, k, p in zip(tasks, keys, params, strict=True):
                outcome, s = task.reset(k, physics, outcome, p)
                states.append(s)
            return outcome, tuple(states)

        def initialize(key, physics, dynamics_params, params):
            for i, (task, p) in enumerate(zip(tasks, params, strict=True)):
                physics = task.initialize(jax.random.fold_in(key, i), physics, dynamics_params, p)
            return physics

        def update(states, outcome, transition, params):
            new_states = []
            for task, s, p in zip(tasks, states, params, strict=True):
                outcome, s = task.update(s, outcome, transition, p)
                new_states.append(s)
            return outcome, tuple(new_states)

        horizons = [t.horizon for t in tasks if t.horizon is not None]
        return Task(update=update, reset=reset, initialize=initialize,
                    default_params=lambda: tuple(t.default_params() for t in tasks),
                    horizon=min(horizons) if horizons else None,
                    has_success=any(t.has_success for t in tasks),
                    name="chain(" + ", ".join(t.name for t in tasks) + ")")
