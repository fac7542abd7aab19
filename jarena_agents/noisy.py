"""``noisy(agent, ...)``: any agent acting less than perfectly, for demonstrations mixed with noisier ones.

Agent-Arena collects its cloth datasets from oracles with noise (``noisy-oracle-towel``) and mixes policies step by
step (``MixPolicy``); a world model learned offline needs such data to see what other actions do. ``noisy`` wraps
any agent: in each arena and step, with probability ``random_fraction`` the action is drawn uniformly from the
action spec (``Spec.sample``), otherwise it is the agent's action with Gaussian noise added to every float ``Box``
element, its standard deviation ``action_noise`` times the element's half range (``(high - low) / 2``; 1 where a
bound is infinite), clipped to the bounds. Integer, boolean and ``Discrete`` actions are only replaced, never
perturbed. The wrapped agent is told the action that was executed (``update``) and keeps its own state; with
both amounts 0 it acts exactly as the bare agent.

    agent = noisy(build_agent("oracle_cloth_flattening"), action_noise=0.1, random_fraction=0.1)

or from the command line, ``jarena collect AGENT ARENA --action-noise 0.1 --random-actions 0.1 ...``.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jarena.core import spec as specs
from jarena.core.agent import Agent

#: Folded into the step's key for the noise, so the wrapped agent receives the key it would have alone.
_NOISE_STREAM = 0x4E015E


@struct.dataclass
class NoisyState:
    """The wrapped agent's state and the action spec (static)."""

    inner: Any
    spec: Any = struct.field(pytree_node=False)


def _check_amount(value: float, name: str, upper: float | None) -> float:
    value = float(value)
    if not math.isfinite(value) or value < 0 or (upper is not None and value > upper):
        valid = f"a number in [0, {upper:g}]" if upper is not None else "a finite number >= 0"
        raise ValueError(f"noisy: {name} must be {valid}, got {value!r}")
    return value


def _perturb(spec: specs.Spec, action: Any, key: jax.Array, scale: float) -> Any:
    """One arena's ``action`` with Gaussian noise on its float Box leaves (std ``scale`` half ranges), clipped."""
    if isinstance(spec, specs.Dict):
        keys = jax.random.split(key, max(len(spec.spaces), 1))
        return {k: _perturb(s, action[k], kk, scale) for (k, s), kk in zip(spec.spaces.items(), keys, strict=False)}
    if isinstance(spec, specs.Tuple):
        keys = jax.random.split(key, max(len(spec.spaces), 1))
        return tuple(_perturb(s, a, kk, scale) for s, a, kk in zip(spec.spaces, action, keys, strict=False))
    if isinstance(spec, specs.Box) and jnp.issubdtype(spec.dtype, jnp.floating):
        with np.errstate(invalid="ignore"):  # inf - inf where a bound is infinite: replaced by 1 below
            half_range = np.where(np.isfinite(spec.low) & np.isfinite(spec.high), (spec.high - spec.low) / 2, 1.0)
        noisy_action = action + scale * jnp.asarray(half_range, action.dtype) * jax.random.normal(
            key, action.shape, action.dtype)
        return jnp.clip(noisy_action, jnp.asarray(spec.low, action.dtype), jnp.asarray(spec.high, action.dtype))
    return action  # integer, boolean and discrete actions are only replaced


def noisy(agent: Agent, *, action_noise: float = 0.0, random_fraction: float = 0.0) -> Agent:
    """``agent`` with exploration noise (see the module's docstring).

    Args:
      agent: any agent.
      action_noise: standard deviation of the Gaussian noise on float Box actions, in half ranges of each
        element (0.1 on a ``[-1, 1]`` action: 0.1), >= 0.
      random_fraction: probability, per arena and step, of a uniformly random action instead, in [0, 1].

    Returns:
      An agent named ``noisy(<name>)`` with the wrapped agent's ``privileged`` and ``made_for``.
    """
    action_noise = _check_amount(action_noise, "action_noise", None)
    random_fraction = _check_amount(random_fraction, "random_fraction", 1.0)

    def init(key, spec, num_arenas):
        return NoisyState(agent.init(key, spec, num_arenas), specs.as_spec(spec.action))

    def act(state, info, key, privileged=None):
        action, inner = agent.act(state.inner, info, key, privileged)
        if not (action_noise or random_fraction):  # the bare agent: no keys to draw in the step
            return action, state.replace(inner=inner)
        batch = info.reward.shape[0]
        keys = jax.random.split(jax.random.fold_in(key, _NOISE_STREAM), (batch, 3))

        def one(action, keys):
            perturbed = _perturb(state.spec, action, keys[0], action_noise) if action_noise else action
            if not random_fraction:
                return perturbed
            replace = jax.random.bernoulli(keys[1], random_fraction)
            return jax.tree_util.tree_map(lambda r, a: jnp.where(replace, r, a).astype(a.dtype),
                                          state.spec.sample(keys[2]), perturbed)

        return jax.vmap(one)(action, keys), state.replace(inner=inner)

    return Agent(
        name=f"noisy({agent.name})", init=init, act=act,
        reset=lambda state, mask: state.replace(inner=agent.reset(state.inner, mask)),
        update=lambda state, info, action: state.replace(inner=agent.update(state.inner, info, action)),
        success=lambda state, info: agent.success(state.inner, info),
        terminate=lambda state, info: agent.terminate(state.inner, info),
        phase=lambda state, info: agent.phase(state.inner, info),
        batch_state=lambda state, num_arenas: state.replace(inner=agent.batch_state(state.inner, num_arenas)),
        privileged=agent.privileged,
        config={"agent": agent.config, "action_noise": action_noise, "random_fraction": random_fraction},
        made_for=agent.made_for)
