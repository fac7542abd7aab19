"""The model a planner rolls forward: a pure ``step(state, action) -> (state, reward, done)``.

:func:`arena_model` builds the exact model of an arena: the arena's own pure ``step`` on the privileged
:class:`~jarena.core.types.ArenaState` (what ``arena.privileged`` hands to privileged agents), with the
arena params fixed when the model is built. The planners only call ``Model.step`` and read the action
bounds, so a learned dynamics model (any pure ``step`` over its own state pytree) can replace it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.arena import Arena
from jarena.core.spec import Box
from jarena.core.types import ArenaParams

PyTree = Any


@dataclasses.dataclass(frozen=True, eq=False)
class Model:
    """A pure, deterministic model of one arena (no batch axis; planners vmap it).

    Attributes:
      step: ``(state, action) -> (state, reward, done)``; ``action`` of ``action_spec.shape``, float32
        ``reward`` and bool ``done`` scalars (the episode ended at this step: terminated or truncated).
      action_spec: a bounded float :class:`~jarena.core.spec.Box`; planners sample and clip in it.
      no_op: the action that applies no actuation (``action_spec.shape``), used to start and pad plans.
      state_shape: ``jax.ShapeDtypeStruct`` pytree of one state, to check planner inputs against
        (``None``: not checked).
      name: for messages.
    """

    step: Callable[[PyTree, jax.Array], tuple[PyTree, jax.Array, jax.Array]]
    action_spec: Box
    no_op: np.ndarray
    state_shape: PyTree = None
    name: str = "model"

    def __post_init__(self):
        check_action_spec(self.action_spec, self.name)

    def check_state(self, state: PyTree, batch_dims: int = 0) -> None:
        """Raises ``ValueError`` (at trace time) when ``state`` (with ``batch_dims`` leading axes) does not
        have this model's state structure, shapes and dtypes."""
        if self.state_shape is None:
            return
        want_tree = jax.tree_util.tree_structure(self.state_shape)
        got_tree = jax.tree_util.tree_structure(state)
        if want_tree != got_tree:
            raise ValueError(f"the state given to the planner does not fit model {self.name!r} (is the agent run "
                             f"in the arena it was built for?): expected state structure {want_tree}, "
                             f"got {got_tree}")
        wanted = jax.tree_util.tree_flatten_with_path(self.state_shape)[0]
        for (path, want), got in zip(wanted, jax.tree_util.tree_leaves(state), strict=True):
            got_shape, got_dtype = tuple(np.shape(got))[batch_dims:], jnp.result_type(got)
            if got_shape != tuple(want.shape) or got_dtype != want.dtype:
                raise ValueError(f"the state given to the planner does not fit model {self.name!r}: "
                                 f"state{jax.tree_util.keystr(path)} has shape {got_shape} and dtype {got_dtype}, "
                                 f"expected {tuple(want.shape)} and {want.dtype}")


def is_bounded_continuous(spec: Any) -> bool:
    """Whether ``spec`` is a float Box with finite bounds (what sampling planners sample and clip plans in)."""
    return isinstance(spec, Box) and np.issubdtype(spec.dtype, np.floating) and spec.bounded


def check_action_spec(spec: Any, name: str) -> Box:
    """Returns ``spec`` if it is a bounded float Box, else raises ``ValueError`` naming what is needed."""
    if not is_bounded_continuous(spec):
        raise ValueError(f"sampling planners need a bounded continuous action spec (a float Box with finite "
                         f"bounds); {name!r} has {spec!r}")
    return spec


def arena_model(arena: Arena, params: ArenaParams | None = None) -> Model:
    """The exact model of ``arena``: ``arena.step`` on the privileged state with fixed ``params``
    (default: ``arena.default_params()``). ``done`` is ``info.terminated | info.truncated``."""
    name = arena.build_string or arena.name
    if arena.dynamics.on_host:
        raise ValueError("its simulator runs on the host (a host arena), whose states cannot be copied or rolled "
                         "forward; plan over a learned model instead (planet)")
    check_action_spec(arena.action_spec, name)
    state_shape = jax.eval_shape(arena.privileged, arena.reset_shapes[0] if params is None else
                                 jax.eval_shape(lambda: arena.reset(jax.random.key(0), params)[0]))
    params = arena.default_params() if params is None else params

    def step(state, action):
        state, info = arena.step(state, action, params)
        return state, info.reward, info.done

    no_op = np.asarray(jax.device_get(arena.no_op()), np.float32)
    return Model(step=step, action_spec=arena.action_spec, no_op=no_op, state_shape=state_shape, name=name)
