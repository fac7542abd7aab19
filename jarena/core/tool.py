"""Action tools: composable transforms from the agent's action to the dynamics' low-level control.

An :class:`ActionTool` wraps the low-level step as *middleware*: its ``step`` receives the action and
an ``inner(carry, control) -> (carry, outcome)`` function that advances the dynamics and task by one
low-level step, and may call it any number of times (``repeat``) or transform the action before
(``rescale``, ``clip``, ``noise``, ``delay``, ``sticky``). The carry is opaque to the tool. Tools
compose with :func:`chain`: the first tool receives the agent's action, the last drives the dynamics.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax

from jarena.core.spec import Spec
from jarena.core.types import Outcome

PyTree = Any
Inner = Callable[[PyTree, PyTree], tuple[PyTree, Outcome]]


def _no_params() -> tuple:
    return ()


def _no_state(key, params, inner_spec):
    return ()


def _same_spec(inner_spec: Spec) -> Spec:
    return inner_spec


def _same_no_op(inner_no_op, inner_spec):
    return inner_no_op


def _pass_through(state, action, carry, inner, params, inner_spec):
    carry, outcome = inner(carry, action)
    return carry, outcome, state


@dataclasses.dataclass(frozen=True)
class ActionTool:
    """An action-tool transform.

    Attributes:
      step: ``(state, action, carry, inner, params, inner_spec) -> (carry, outcome, state)``.
        ``inner_spec`` is the (static) spec of what this tool emits.
      reset: ``(key, params, inner_spec) -> state`` at episode start.
      spec: ``inner_spec -> spec`` of the actions this tool accepts (static).
      no_op: ``(inner_no_op, inner_spec) -> no-op action`` in this tool's action space.
      default_params: ``() -> params`` pytree.
      substeps: static number of inner calls per step (an upper bound for early-stopping tools).
      name: a short name for messages.
    """

    step: Callable[..., tuple[PyTree, Outcome, PyTree]] = _pass_through
    reset: Callable[[jax.Array, PyTree, Spec], PyTree] = _no_state
    spec: Callable[[Spec], Spec] = _same_spec
    no_op: Callable[[PyTree, Spec], PyTree] = _same_no_op
    default_params: Callable[[], PyTree] = _no_params
    substeps: int = 1
    name: str = "tool"

    @staticmethod
    def chain(*tools: ActionTool) -> ActionTool:
        """Composes tools: ``tools[0]`` receives the agent's action, ``tools[-1]`` emits control."""
        for t in tools:
            if not isinstance(t, ActionTool):
                raise TypeError(f"chain of action tools got {t!r}, which is not an ActionTool")
        n = len(tools)

        def inner_specs(control_spec):
            """specs[k] is what tool k emits; specs[n] is the control spec."""
            specs = [control_spec]
            for t in reversed(tools):
                specs.insert(0, t.spec(specs[0]))
            return specs[1:]

        def spec(control_spec):
            return tools[0].spec(inner_specs(control_spec)[0]) if tools else control_spec

        def no_op(control_no_op, control_spec):
            specs = inner_specs(control_spec)
            action = control_no_op
            for t, s in zip(reversed(tools), reversed(specs), strict=True):
                action = t.no_op(action, s)
            return action

        def reset(key, params, control_spec):
            keys = [jax.random.fold_in(key, i) for i in range(n)]
            return tuple(t.reset(k, p, s) for t, k, p, s in
                         zip(tools, keys, params, inner_specs(control_spec), strict=True))

        def step(states, action, carry, inner, params, control_spec):
            specs = inner_specs(control_spec)

            def level(k):
                # Returns the inner function for tool k-1: (carry, states[k:]) x action.
                if k == n:
                    def innermost(ext, control):
                        base, _ = ext
                        base, outcome = inner(base, control)
                        return (base, ()), outcome
                    return innermost
                deeper = level(k + 1)

                def at_k(ext, a):
                    base, sts = ext
                    (base, rest), outcome, s_k = tools[k].step(sts[0], a, (base, sts[1:]), deeper, params[k],
                                                               specs[k])
                    return (base, (s_k,) + tuple(rest)), outcome
                return at_k

            (carry, states), outcome = level(0)((carry, tuple(states)), action)
            return carry, outcome, states

        substeps = 1
        for t in tools:
            substeps *= t.substeps
        return ActionTool(step=step, reset=reset, spec=spec, no_op=no_op,
                          default_params=lambda: tuple(t.default_params() for t in tools),
                          substeps=substeps, name="chain(" + ", ".join(t.name for t in tools) + ")")
