"""Flax networks for agents: observation flattening, MLP torsos and policy distributions."""

from __future__ import annotations

from collections.abc import Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.arena import ArenaSpec
from jarena.core.spec import Box, Discrete, Spec
from jarena.core.types import Info


def observation_size(spec: ArenaSpec) -> int:
    """Length of :func:`flatten_observation`'s output for an arena of ``spec``."""
    leaves = jax.tree_util.tree_leaves(spec.observation.zeros())
    return int(sum(np.prod(x.shape, dtype=int) for x in leaves)) + spec.goal_dim


def flatten_observation(info: Info, batch_dims: int = 1) -> jax.Array:
    """Concatenates every observation leaf (sorted by key) and the goal into float32 (*batch, D)."""
    leaves = jax.tree_util.tree_leaves(info.observation) + [info.goal]
    batch = leaves[0].shape[:batch_dims]
    return jnp.concatenate([x.reshape(batch + (-1,)).astype(jnp.float32) for x in leaves], axis=-1)


class MLP(nn.Module):
    """``hidden`` tanh layers then a linear output of ``features`` (orthogonal initialisation)."""

    hidden: Sequence[int]
    features: int
    output_scale: float = 1.0

    @nn.compact
    def __call__(self, x):
        for width in self.hidden:
            x = nn.tanh(nn.Dense(width, kernel_init=nn.initializers.orthogonal(np.sqrt(2)))(x))
        return nn.Dense(self.features, kernel_init=nn.initializers.orthogonal(self.output_scale))(x)


class ActorCritic(nn.Module):
    """Separate policy and value MLPs. Returns ``(policy outputs, value)``.

    Policy outputs: logits (*, n) for Discrete actions; mean (*, d) for Box actions, with a learned
    state-independent log standard deviation. ``value_hidden`` sizes the value MLP (default: ``hidden``).
    """

    action_spec: Spec
    hidden: Sequence[int] = (64, 64)
    value_hidden: Sequence[int] | None = None

    @nn.compact
    def __call__(self, x):
        value_hidden = self.hidden if self.value_hidden is None else self.value_hidden
        value = MLP(value_hidden, 1, output_scale=1.0, name="critic")(x)[..., 0]
        if isinstance(self.action_spec, Discrete):
            return MLP(self.hidden, self.action_spec.n, output_scale=0.01, name="actor")(x), value
        dim = int(np.prod(self.action_spec.shape))
        mean = MLP(self.hidden, dim, output_scale=0.01, name="actor")(x)
        log_std = self.param("log_std", nn.initializers.zeros, (dim,))
        return (mean, jnp.broadcast_to(log_std, mean.shape)), value


def check_supported(spec: Spec, agent: str) -> None:
    if isinstance(spec, Discrete):
        return
    if isinstance(spec, Box) and spec.bounded and spec.dtype.kind == "f":
        return
    raise TypeError(f"{agent} supports Discrete or bounded float Box actions, got {spec!r}")


def sample_action(spec: Spec, policy, key, deterministic: bool):
    """Samples (or takes the mode of) the policy; returns ``(raw action, log prob, entropy)``.

    For Box actions the raw action is the Gaussian sample in normalised units; :func:`to_env_action`
    maps it into the spec's bounds.
    """
    if isinstance(spec, Discrete):
        logits = policy
        action = jnp.argmax(logits, -1) if deterministic else jax.random.categorical(key, logits)
        return action.astype(jnp.int32), log_prob(spec, policy, action), entropy(spec, policy)
    mean, log_std = policy
    action = mean if deterministic else mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape)
    return action, log_prob(spec, policy, action), entropy(spec, policy)


def log_prob(spec: Spec, policy, action):
    if isinstance(spec, Discrete):
        logp = jax.nn.log_softmax(policy)
        return jnp.take_along_axis(logp, action[..., None].astype(jnp.int32), -1)[..., 0]
    mean, log_std = policy
    z = (action - mean) / jnp.exp(log_std)
    return jnp.sum(-0.5 * z**2 - log_std - 0.5 * jnp.log(2 * jnp.pi), -1)


def entropy(spec: Spec, policy):
    if isinstance(spec, Discrete):
        logp = jax.nn.log_softmax(policy)
        return -jnp.sum(jnp.exp(logp) * logp, -1)
    _, log_std = policy
    return jnp.sum(log_std + 0.5 * jnp.log(2 * jnp.pi * jnp.e), -1)


def to_env_action(spec: Spec, raw):
    """Maps a raw policy action into the arena's action space (Box: clip to [-1, 1], rescale)."""
    if isinstance(spec, Discrete):
        return raw
    low, high = jnp.asarray(spec.low, jnp.float32), jnp.asarray(spec.high, jnp.float32)
    unit = jnp.clip(raw, -1.0, 1.0).reshape(raw.shape[:-1] + spec.shape)
    return (low + (unit + 1.0) * 0.5 * (high - low)).astype(spec.dtype)
