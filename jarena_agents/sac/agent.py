"""SAC (Haarnoja et al., 2018, "SAC v2") as a jarena agent that trains end to end on device.

Twin Q critics with Polyak-averaged target copies, a tanh-squashed Gaussian actor, and automatic tuning
of the entropy temperature ``alpha`` toward a target entropy (``-|A|`` by default). Continuous (bounded
``Box``) actions only; the actor's ``tanh`` output in (-1, 1) is scaled affinely to the action bounds.

One *update* of ``train`` is ``rollout_length`` steps of all ``num_arenas`` auto-resetting arenas
(``steps_per_update = num_arenas * rollout_length`` environment steps, added to an on-device replay
buffer of :func:`jarena.data.make_buffer` as they happen) followed by
``gradient_steps = utd * steps_per_update`` gradient steps, each on a fresh minibatch sampled uniformly
from the buffer. The defaults (``rollout_length = 1``) alternate one step of all arenas with its
gradient steps, as in the paper. Until ``learning_starts`` environment steps have been taken the
actions are uniform in the bounds and no gradient step runs. Transitions take the next observation
from ``info.final`` and bootstrap through truncation (only ``terminated`` stops bootstrapping).

The buffer lives in the train state, so a checkpoint holds it and a resumed run continues bit for bit;
a whole run is a function of a key, so seeds ``vmap``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from jarena import distributed
from jarena.core.agent import Agent
from jarena.core.arena import Arena, ArenaSpec
from jarena.core.batching import batch_reset, batch_step
from jarena.core.spec import Box, Spec
from jarena.core.types import ArenaState, Info
from jarena.data import BufferState, make_buffer
from jarena_agents import networks
from jarena_agents.config import (
    ArenaSchedule,
    at_least,
    in_unit_interval,
    make_config,
    non_negative,
    positive,
    rounded_buffer,
    unbounded,
)
from jarena_agents.registry import register_agent
from jarena_agents.sac import losses
from jarena_agents.trainable import TrainableAgent

PyTree = Any


@dataclasses.dataclass(frozen=True)
class SACConfig(ArenaSchedule):
    """SAC hyperparameters (defaults: the paper's, as in Stable-Baselines3 and CleanRL).

    Attributes:
      num_arenas: arenas stepped together.
      rollout_length: steps of every arena per update (before its gradient steps).
      utd: update-to-data ratio: gradient steps per environment step; ``utd * num_arenas * rollout_length``
        (the gradient steps per update) must be a positive integer.
      batch_size: transitions per gradient step.
      buffer_size: replay capacity in transitions (rounded down to a multiple of ``num_arenas``, with a warning).
      learning_starts: environment steps of uniform-random actions before learning.
      total_steps: environment steps of a run.
      discount: gamma.
      tau: Polyak coefficient of the target critics (``target <- tau * online + (1 - tau) * target``).
      actor_lr: Adam learning rate of the actor.
      critic_lr: Adam learning rate of the critics.
      alpha_lr: Adam learning rate of the temperature ``alpha``.
      initial_alpha: the temperature at the start.
      autotune_alpha: tune ``alpha`` toward ``target_entropy``; if false it stays ``initial_alpha``.
      target_entropy: nats; ``None`` means ``-|A|`` (minus the number of action dimensions).
      hidden: widths of the ReLU layers of the actor and of each critic.
      log_std_min: lower bound of the actor's log standard deviation (before ``tanh``).
      log_std_max: upper bound of the actor's log standard deviation (before ``tanh``).
      reward_scale: rewards are multiplied by this in the critic's target.
    """

    num_arenas: int = at_least(1, default=1)
    rollout_length: int = at_least(1, default=1)
    utd: float = positive(1.0)
    batch_size: int = at_least(1, default=256)
    buffer_size: int = at_least(1, default=1_000_000)
    learning_starts: int = non_negative(5_000)
    total_steps: int = at_least(1, default=1_000_000)
    discount: float = in_unit_interval(0.99, open_low=True)
    tau: float = in_unit_interval(0.005, open_low=True)
    actor_lr: float = positive(3e-4)
    critic_lr: float = positive(3e-4)
    alpha_lr: float = positive(3e-4)
    initial_alpha: float = positive(1.0)
    autotune_alpha: bool = True
    target_entropy: float | None = unbounded(None)
    hidden: tuple = (256, 256)
    log_std_min: float = unbounded(-5.0)
    log_std_max: float = unbounded(2.0)
    reward_scale: float = positive(1.0)

    @property
    def gradient_steps(self) -> int:
        """Gradient steps per update: ``utd * steps_per_update``."""
        return int(round(self.utd * self.steps_per_update))


def _check_config(cfg: SACConfig) -> None:
    def fail(message):
        raise ValueError(f"sac: {message}")

    grad = cfg.utd * cfg.steps_per_update  # ranges of single keys: SACConfig's fields, checked by make_config
    if cfg.utd <= 0 or abs(grad - round(grad)) > 1e-9:
        fail(f"utd * num_arenas * rollout_length (gradient steps per update) must be a positive integer, got "
             f"{cfg.utd} * {cfg.num_arenas} * {cfg.rollout_length} = {grad}")
    if cfg.target_entropy is not None and not isinstance(cfg.target_entropy, int | float):
        fail(f"target_entropy must be a number or null (for -|A|), got {cfg.target_entropy!r}")
    if not cfg.log_std_min < cfg.log_std_max:
        fail(f"log_std_min={cfg.log_std_min} must be below log_std_max={cfg.log_std_max}")


def action_dim(spec: Spec) -> int:
    """|A|: the number of action dimensions; raises TypeError unless ``spec`` is a bounded float Box."""
    if not (isinstance(spec, Box) and spec.bounded and np.dtype(spec.dtype).kind == "f"):
        raise TypeError(f"sac supports only continuous actions (a bounded float Box action spec), got {spec!r}; "
                        "for Discrete actions use an agent such as 'ppo'")
    return int(np.prod(spec.shape, dtype=int))


def to_env_action(spec: Box, unit: jax.Array) -> jax.Array:
    """Maps actions in [-1, 1], (*, |A|), affinely to the spec's bounds, (*, *spec.shape)."""
    low, high = jnp.asarray(spec.low, jnp.float32), jnp.asarray(spec.high, jnp.float32)
    unit = unit.reshape(unit.shape[:-1] + spec.shape)
    return (low + (unit + 1.0) * 0.5 * (high - low)).astype(spec.dtype)


class Actor(nn.Module):
    """ReLU MLP to the mean and log standard deviation (*, D) of the Gaussian before ``tanh``.

    ``log_std`` is squashed smoothly into ``[log_std_min, log_std_max]``.
    """

    action_dim: int
    hidden: Sequence[int]
    log_std_min: float = -5.0
    log_std_max: float = 2.0

    @nn.compact
    def __call__(self, observation):
        x = observation
        for width in self.hidden:
            x = nn.relu(nn.Dense(width)(x))
        mean = nn.Dense(self.action_dim, name="mean")(x)
        log_std = jnp.tanh(nn.Dense(self.action_dim, name="log_std")(x))
        log_std = self.log_std_min + 0.5 * (self.log_std_max - self.log_std_min) * (log_std + 1.0)
        return mean, log_std


class QNetwork(nn.Module):
    """ReLU MLP of the concatenated observation (*, O) and action (*, D) to Q (*,)."""

    hidden: Sequence[int]

    @nn.compact
    def __call__(self, observation, action):
        x = jnp.concatenate([observation, action], axis=-1)
        for width in self.hidden:
            x = nn.relu(nn.Dense(width)(x))
        return nn.Dense(1)(x)[..., 0]


class TwinCritic(nn.Module):
    """Two independent :class:`QNetwork` s (stacked parameters, one batched call); returns ``(q1, q2)``."""

    hidden: Sequence[int]

    @nn.compact
    def __call__(self, observation, action):
        twins = nn.vmap(QNetwork, variable_axes={"params": 0}, split_rngs={"params": True}, in_axes=None,
                        out_axes=0, axis_size=2)
        q = twins(self.hidden, name="q")(observation, action)
        return q[0], q[1]


@struct.dataclass
class SACState:
    """Acting state: the actor's parameters; ``deterministic`` selects eval mode (static)."""

    actor_params: PyTree
    spec: ArenaSpec = struct.field(pytree_node=False)
    deterministic: bool = struct.field(pytree_node=False, default=False)


@struct.dataclass
class SACTrainState:
    """Everything a run needs to continue bit for bit (networks, optimisers, replay buffer, arenas, RNG)."""

    actor_params: PyTree
    critic_params: PyTree
    target_critic_params: PyTree
    log_alpha: jax.Array  # float32 scalar
    actor_opt_state: PyTree
    critic_opt_state: PyTree
    alpha_opt_state: PyTree
    buffer: BufferState
    arena_state: ArenaState
    info: Info
    episode_return: jax.Array  # (B,) return of the running episodes
    key: jax.Array
    update: jax.Array  # int32, updates done
    env_steps: jax.Array  # int32 environment steps taken over all arenas


@struct.dataclass
class _Learner:
    """The parameters and optimiser states that gradient steps change."""

    actor_params: PyTree
    critic_params: PyTree
    target_critic_params: PyTree
    log_alpha: jax.Array
    actor_opt_state: PyTree
    critic_opt_state: PyTree
    alpha_opt_state: PyTree


METRICS = ("critic_loss", "actor_loss", "alpha_loss", "alpha", "entropy", "q", "target_q")


def make_sac(config=None) -> TrainableAgent:
    cfg = rounded_buffer(make_config(SACConfig, config, agent="sac"), "sac")
    _check_config(cfg)
    buffer = make_buffer(cfg.num_arenas, cfg.buffer_size, cfg.batch_size, mode="transition")
    actor_opt, critic_opt, alpha_opt = (optax.adam(cfg.actor_lr), optax.adam(cfg.critic_lr), optax.adam(cfg.alpha_lr))
    critic = TwinCritic(tuple(cfg.hidden))

    def actor(spec: ArenaSpec) -> Actor:
        return Actor(action_dim(spec.action), tuple(cfg.hidden), cfg.log_std_min, cfg.log_std_max)

    def target_entropy(spec: ArenaSpec) -> float:
        return -float(action_dim(spec.action)) if cfg.target_entropy is None else float(cfg.target_entropy)

    def init(key, spec: ArenaSpec, num_arenas: int) -> SACState:
        params = actor(spec).init(key, jnp.zeros((1, networks.observation_size(spec)), jnp.float32))
        return SACState(actor_params=params, spec=spec)

    def unit_action(spec, actor_params, observation, key, deterministic: bool):
        mean, log_std = actor(spec).apply(actor_params, observation)
        if deterministic:
            return jnp.tanh(mean)
        return losses.sample_squashed_gaussian(key, mean, log_std)[0]

    def act(state: SACState, info: Info, key, privileged=None):
        unit = unit_action(state.spec, state.actor_params, networks.flatten_observation(info), key,
                           state.deterministic)
        return to_env_action(state.spec.action, unit), state

    def policy(train_state: SACTrainState, spec: ArenaSpec, deterministic: bool = True) -> SACState:
        """The acting state of a trained agent (eval mode: ``tanh`` of the mean, no sampling)."""
        return SACState(actor_params=train_state.actor_params, spec=spec, deterministic=deterministic)

    def buffer_item(spec: ArenaSpec) -> dict:
        dim, a = networks.observation_size(spec), action_dim(spec.action)
        f32 = jax.ShapeDtypeStruct
        return dict(observation=f32((dim,), jnp.float32), action=f32((a,), jnp.float32),
                    reward=f32((), jnp.float32), terminated=f32((), jnp.bool_), truncated=f32((), jnp.bool_),
                    next_observation=f32((dim,), jnp.float32), episode=f32((), jnp.int32),
                    step=f32((), jnp.int32))

    def init_training(key, arena: Arena) -> SACTrainState:
        spec = arena.spec
        key, actor_key, critic_key, reset_key = jax.random.split(key, 4)
        actor_params = init(actor_key, spec, cfg.num_arenas).actor_params
        dim, a = networks.observation_size(spec), action_dim(spec.action)
        critic_params = critic.init(critic_key, jnp.zeros((1, dim), jnp.float32), jnp.zeros((1, a), jnp.float32))
        log_alpha = jnp.asarray(np.log(cfg.initial_alpha), jnp.float32)
        arena_state, info = batch_reset(arena, reset_key, cfg.num_arenas)
        return SACTrainState(
            actor_params=actor_params, critic_params=critic_params,
            target_critic_params=jax.tree_util.tree_map(jnp.copy, critic_params), log_alpha=log_alpha,
            actor_opt_state=actor_opt.init(actor_params), critic_opt_state=critic_opt.init(critic_params),
            alpha_opt_state=alpha_opt.init(log_alpha), buffer=buffer.init(buffer_item(spec)),
            arena_state=arena_state, info=info, episode_return=jnp.zeros((cfg.num_arenas,), jnp.float32), key=key,
            update=jnp.zeros((), jnp.int32), env_steps=jnp.zeros((), jnp.int32))

    def gradient_step(spec: ArenaSpec, buffer_state: BufferState, learner: _Learner, key):
        sample_key, next_key, actor_key = jax.random.split(key, 3)
        # data parallel over the devices of a mesh (jarena.distributed): each device takes its share of the
        # minibatch, the networks stay whole on each, and XLA all-reduces the gradients
        learner = distributed.replicate(learner)
        batch = distributed.split_batch(buffer.sample(buffer_state, sample_key).experience)
        alpha = jnp.exp(learner.log_alpha)
        net = actor(spec)

        # Critics: soft Bellman residual against the target critics at actions of the current actor.
        next_mean, next_log_std = net.apply(learner.actor_params, batch["next_observation"])
        next_action, next_log_prob = losses.sample_squashed_gaussian(next_key, next_mean, next_log_std)
        next_q1, next_q2 = critic.apply(learner.target_critic_params, batch["next_observation"], next_action)

        def critic_objective(params):
            q1, q2 = critic.apply(params, batch["observation"], batch["action"])
            return losses.critic_loss(q1, q2, next_q1, next_q2, next_log_prob, batch["reward"] * cfg.reward_scale,
                                      batch["terminated"], alpha, cfg.discount)

        grads, critic_terms = jax.grad(critic_objective, has_aux=True)(learner.critic_params)
        updates, critic_opt_state = critic_opt.update(grads, learner.critic_opt_state, learner.critic_params)
        critic_params = optax.apply_updates(learner.critic_params, updates)

        # Actor: reparameterised actions against the updated critics.
        def actor_objective(params):
            mean, log_std = net.apply(params, batch["observation"])
            action, log_prob = losses.sample_squashed_gaussian(actor_key, mean, log_std)
            q1, q2 = critic.apply(critic_params, batch["observation"], action)
            return losses.actor_loss(log_prob, q1, q2, alpha), log_prob

        (actor_value, log_prob), grads = jax.value_and_grad(actor_objective, has_aux=True)(learner.actor_params)
        updates, actor_opt_state = actor_opt.update(grads, learner.actor_opt_state, learner.actor_params)
        actor_params = optax.apply_updates(learner.actor_params, updates)

        # Temperature: toward the target entropy, from the log densities of the actor before its step.
        alpha_value, grad = jax.value_and_grad(losses.temperature_loss)(learner.log_alpha, log_prob,
                                                                         target_entropy(spec))
        log_alpha, alpha_opt_state = learner.log_alpha, learner.alpha_opt_state
        if cfg.autotune_alpha:
            updates, alpha_opt_state = alpha_opt.update(grad, alpha_opt_state, log_alpha)
            log_alpha = optax.apply_updates(log_alpha, updates)

        learner = _Learner(actor_params=actor_params, critic_params=critic_params,
                           target_critic_params=losses.polyak_update(learner.target_critic_params, critic_params,
                                                                     cfg.tau),
                           log_alpha=log_alpha, actor_opt_state=actor_opt_state, critic_opt_state=critic_opt_state,
                           alpha_opt_state=alpha_opt_state)
        learner = distributed.replicate(learner)
        metrics = dict(critic_loss=critic_terms.loss, actor_loss=actor_value, alpha_loss=alpha_value, alpha=alpha,
                       entropy=-jnp.mean(log_prob), q=0.5 * (critic_terms.q1 + critic_terms.q2),
                       target_q=critic_terms.target)
        return learner, metrics

    def one_update(arena: Arena, ts: SACTrainState):
        spec = arena.spec
        arena_params = arena.default_params()
        dim = action_dim(spec.action)

        def env_step(carry, xs):
            arena_state, info, episode_return, buffer_state = carry
            index, key = xs
            policy_key, random_key = jax.random.split(key)
            observation = networks.flatten_observation(info)
            explore = ts.env_steps + index * cfg.num_arenas < cfg.learning_starts
            unit = jnp.where(explore, jax.random.uniform(random_key, (cfg.num_arenas, dim), jnp.float32, -1.0, 1.0),
                             unit_action(spec, ts.actor_params, observation, policy_key, False))
            arena_state, next_info = batch_step(arena, arena_state, to_env_action(spec.action, unit), arena_params)
            next_observation = networks.flatten_observation(
                next_info.replace(observation=next_info.final.observation, goal=next_info.final.goal))
            buffer_state = buffer.add(buffer_state, dict(
                observation=observation, action=unit, reward=next_info.reward, terminated=next_info.terminated,
                truncated=next_info.truncated, next_observation=next_observation, episode=info.episode,
                step=info.step))
            episode_return = episode_return + next_info.reward
            finished = next_info.done
            record = dict(done=finished, finished_return=jnp.where(finished, episode_return, 0.0),
                          faulted=next_info.faulted)
            episode_return = jnp.where(finished, 0.0, episode_return)
            return (arena_state, next_info, episode_return, buffer_state), record

        key, rollout_key, learn_key = jax.random.split(ts.key, 3)
        (arena_state, info, episode_return, buffer_state), record = jax.lax.scan(
            env_step, (ts.arena_state, ts.info, ts.episode_return, ts.buffer),
            (jnp.arange(cfg.rollout_length, dtype=jnp.int32), jax.random.split(rollout_key, cfg.rollout_length)))
        env_steps = ts.env_steps + cfg.steps_per_update

        learner = _Learner(actor_params=ts.actor_params, critic_params=ts.critic_params,
                           target_critic_params=ts.target_critic_params, log_alpha=ts.log_alpha,
                           actor_opt_state=ts.actor_opt_state, critic_opt_state=ts.critic_opt_state,
                           alpha_opt_state=ts.alpha_opt_state)

        def learn(learner):
            learner, metrics = jax.lax.scan(lambda lr, k: gradient_step(spec, buffer_state, lr, k), learner,
                                            jax.random.split(learn_key, cfg.gradient_steps))
            return learner, {k: jnp.mean(v) for k, v in metrics.items()}

        def wait(learner):
            return learner, {k: jnp.zeros((), jnp.float32) for k in METRICS}

        learner, metrics = jax.lax.cond(env_steps >= cfg.learning_starts, learn, wait, learner)
        finished = jnp.sum(record["done"])
        metrics = dict(episodes=finished,
                       episode_return=jnp.sum(record["finished_return"]) / jnp.maximum(finished, 1),
                       faulted_episodes=jnp.sum(record["faulted"]), **metrics)  # a fault ends its episode
        ts = SACTrainState(**{f.name: getattr(learner, f.name) for f in dataclasses.fields(_Learner)},
                           buffer=buffer_state, arena_state=arena_state, info=info, episode_return=episode_return,
                           key=key, update=ts.update + 1, env_steps=env_steps)
        return ts, metrics

    def train(train_state: SACTrainState, arena: Arena, num_updates: int):
        """Runs ``num_updates`` updates (static) in one ``lax.scan``; metrics have a leading update axis."""
        return jax.lax.scan(lambda ts, _: one_update(arena, ts), train_state, None, length=num_updates)

    agent = Agent(name="sac", init=init, act=act, config=dataclasses.asdict(cfg))
    return TrainableAgent.wrap(agent, init_training=init_training, train=train, policy=policy, settings=cfg)


register_agent("sac", make_sac, tags=("trainable", "rl"))
