"""PPO (Schulman et al., 2017) as a jarena agent that trains end to end on device.

Acting follows the agent protocol (``init / act``, state batched over arenas, shared parameters);
training adds ``init_training(key, arena) -> PPOTrainState`` and
``train(train_state, arena, num_updates) -> (train_state, metrics)``, a jittable chunk of updates.
Each update collects ``rollout_length`` steps from ``num_arenas`` auto-resetting arenas, computes GAE
(bootstrapping truncated episodes from ``info.final``), and runs ``epochs`` passes of ``minibatches``
clipped-objective gradient steps; with ``unroll_length`` set, GAE is recomputed in each minibatch over
shuffled segments of that length with the current value network, as Brax's PPO does. A whole run is a
function of a key, so seeds ``vmap``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import optax
from flax import struct

from jarena import distributed
from jarena.core.agent import Agent
from jarena.core.arena import Arena, ArenaSpec
from jarena.core.batching import batch_reset, batch_step
from jarena.core.types import ArenaState, Info
from jarena_agents import networks, normalizer
from jarena_agents.config import ArenaSchedule, at_least, in_unit_interval, make_config, non_negative, positive
from jarena_agents.ppo.losses import compute_gae, ppo_loss, standardized
from jarena_agents.registry import register_agent
from jarena_agents.trainable import TrainableAgent

PyTree = Any


@dataclasses.dataclass(frozen=True)
class PPOConfig(ArenaSchedule):
    """PPO hyperparameters (defaults: PureJaxRL's CartPole settings)."""

    num_arenas: int = at_least(1, default=4)  # arenas stepped together (auto-resetting)
    rollout_length: int = at_least(1, default=128)  # steps of every arena collected per update
    epochs: int = at_least(1, default=4)  # passes over each update's rollout
    # gradient steps per epoch; the rollout's transitions (or unroll_length segments) are split evenly among them
    minibatches: int = at_least(1, default=4)
    learning_rate: float = positive(2.5e-4)  # Adam's (eps 1e-5), at the start if anneal_lr
    anneal_lr: bool = True  # decay the learning rate linearly to 0 over the run's gradient steps
    # environment steps of a run: total_steps // (num_arenas * rollout_length) updates (at least 1)
    total_steps: int = at_least(1, default=500_000)
    discount: float = in_unit_interval(0.99, open_low=True)  # gamma
    gae_lambda: float = in_unit_interval(0.95)  # lambda of GAE (0: one-step TD advantages, 1: Monte Carlo)
    # eps: the probability ratio is clipped to [1 - eps, 1 + eps] in the surrogate objective
    clip_epsilon: float = positive(0.2)
    entropy_coef: float = non_negative(0.01)  # weight of the policy entropy bonus in the loss
    value_coef: float = non_negative(0.5)  # weight of the value loss ((value - return)^2 / 2) in the loss
    max_grad_norm: float | None = positive(0.5)  # None: no clipping (Brax's default)
    hidden: tuple = (64, 64)  # widths of the policy MLP's hidden layers (and the value MLP's by default)
    value_hidden: tuple | None = None  # the value MLP's layers (default: ``hidden``)
    box_policy: str = "gaussian"  # or "tanh_normal" (Brax's): see networks.ActorCritic
    activation: str = "tanh"  # hidden layers: tanh, relu or swish (Brax's)
    # convolutions (features, kernel, stride) for image observations (uint8 (H, W, C) keys, e.g. pixels:64);
    # the Nature DQN's by default; unused on arenas without images
    cnn: tuple = ((32, 8, 4), (64, 4, 2), (64, 3, 1))
    cnn_padding: str = "VALID"  # or "SAME"
    normalize_observations: bool = False  # normalises the vector observations (never the images)
    reward_scale: float = positive(1.0)  # rewards are multiplied by this for GAE (reported returns stay unscaled)
    # None: GAE over the whole rollout with the acting parameters, then transitions are shuffled
    # (PureJaxRL). An int U: the rollout is cut into U-step segments, segments are shuffled, and each
    # minibatch recomputes GAE over its segments with the current value network (Brax's PPO).
    unroll_length: int | None = at_least(1, default=None)



@struct.dataclass
class PPOState:
    """Acting state: shared parameters and normaliser; ``deterministic`` selects eval mode (static)."""

    params: PyTree
    observation_stats: normalizer.RunningStatistics
    spec: ArenaSpec = struct.field(pytree_node=False)
    deterministic: bool = struct.field(pytree_node=False, default=False)


@struct.dataclass
class PPOTrainState:
    """Everything a run needs to continue bit for bit (network, optimiser, normaliser, arenas, RNG)."""

    params: PyTree
    opt_state: PyTree
    observation_stats: normalizer.RunningStatistics
    arena_state: ArenaState
    info: Info
    episode_return: jax.Array  # (B,) return of the running episodes
    key: jax.Array
    update: jax.Array  # int32, updates done
    env_steps: jax.Array  # int32 (wraps past 2^31: use update * steps_per_update for long runs)


def make_ppo(config=None) -> Agent:
    cfg = make_config(PPOConfig, config, agent="ppo")
    if cfg.box_policy not in networks.BOX_POLICIES:
        raise ValueError(f"ppo: unknown box_policy {cfg.box_policy!r}; choose from {', '.join(networks.BOX_POLICIES)}")
    if cfg.cnn_padding not in networks.PADDINGS:
        raise ValueError(f"ppo: unknown cnn_padding {cfg.cnn_padding!r}; choose from {', '.join(networks.PADDINGS)}")
    if cfg.activation not in networks.ACTIVATIONS:
        raise ValueError(f"ppo: unknown activation {cfg.activation!r}; choose from {', '.join(networks.ACTIVATIONS)}")
    if cfg.steps_per_update % cfg.minibatches:
        raise ValueError(f"ppo: num_arenas * rollout_length = {cfg.steps_per_update} must be divisible by "
                         f"minibatches = {cfg.minibatches}")
    unroll = cfg.unroll_length
    if unroll is not None:
        if unroll < 1 or cfg.rollout_length % unroll:
            raise ValueError(f"ppo: unroll_length = {unroll} must be a positive divisor of rollout_length = "
                             f"{cfg.rollout_length}")
        if (cfg.steps_per_update // unroll) % cfg.minibatches:
            raise ValueError(f"ppo: the {cfg.steps_per_update // unroll} segments of unroll_length = {unroll} "
                             f"must be divisible by minibatches = {cfg.minibatches}")

    def network(spec: ArenaSpec):
        networks.check_supported(spec.action, "ppo")
        return networks.ActorCritic(spec.action, tuple(cfg.hidden),
                                    None if cfg.value_hidden is None else tuple(cfg.value_hidden), cfg.box_policy,
                                    activation=cfg.activation, cnn=tuple(tuple(layer) for layer in cfg.cnn),
                                    cnn_padding=cfg.cnn_padding)

    def observe(spec: ArenaSpec, info: Info):
        """What the network reads: the flat observation vector, or with image keys the vector and the images."""
        images = networks.image_keys(spec)
        return networks.split_observation(info, images) if images else networks.flatten_observation(info)

    def vector_of(observation):
        return observation["vector"] if isinstance(observation, dict) else observation

    def optimizer():
        lr = cfg.learning_rate
        if cfg.anneal_lr:
            lr = optax.linear_schedule(cfg.learning_rate, 0.0, cfg.num_updates * cfg.epochs * cfg.minibatches)
        adam = optax.adam(lr, eps=1e-5)
        return adam if cfg.max_grad_norm is None else optax.chain(optax.clip_by_global_norm(cfg.max_grad_norm), adam)

    def forward(spec, params, stats, observation):
        if cfg.normalize_observations:
            if isinstance(observation, dict):
                observation = dict(observation, vector=normalizer.normalize(stats, observation["vector"]))
            else:
                observation = normalizer.normalize(stats, observation)
        return network(spec).apply(params, observation)

    def init(key, spec: ArenaSpec, num_arenas: int) -> PPOState:
        images = networks.image_keys(spec)
        dim = networks.vector_size(spec, images)
        example = jnp.zeros((1, dim), jnp.float32)
        if images:
            example = {"vector": example,
                       "images": {k: spec.observation[k].zeros()[None] for k in images}}
        params = network(spec).init(key, example)
        return PPOState(params=params, observation_stats=normalizer.init(dim), spec=spec)

    def act(state: PPOState, info: Info, key, privileged=None):
        policy, _ = forward(state.spec, state.params, state.observation_stats, observe(state.spec, info))
        raw, _, _ = networks.sample_action(state.spec.action, policy, key, state.deterministic)
        return networks.to_env_action(state.spec.action, raw, policy), state

    def init_training(key, arena: Arena) -> PPOTrainState:
        key, init_key, reset_key = jax.random.split(key, 3)
        acting = init(init_key, arena.spec, cfg.num_arenas)
        arena_state, info = batch_reset(arena, reset_key, cfg.num_arenas)
        return PPOTrainState(params=acting.params, opt_state=optimizer().init(acting.params),
                             observation_stats=acting.observation_stats, arena_state=arena_state, info=info,
                             episode_return=jnp.zeros((cfg.num_arenas,), jnp.float32), key=key,
                             update=jnp.zeros((), jnp.int32), env_steps=jnp.zeros((), jnp.int32))

    def policy(train_state: PPOTrainState, spec: ArenaSpec, deterministic: bool = True) -> PPOState:
        """The acting state of a trained agent (eval mode is deterministic)."""
        return PPOState(params=train_state.params, observation_stats=train_state.observation_stats, spec=spec,
                        deterministic=deterministic)

    def one_update(arena: Arena, ts: PPOTrainState):
        spec = arena.spec
        arena_params = arena.default_params()

        def rollout_step(carry, key):
            arena_state, info, episode_return = carry
            observation = observe(spec, info)
            policy_out, value = forward(spec, ts.params, ts.observation_stats, observation)
            raw, logp, _ = networks.sample_action(spec.action, policy_out, key, False)
            action = networks.to_env_action(spec.action, raw, policy_out)
            arena_state, next_info = batch_step(arena, arena_state, action, arena_params)
            final_observation = observe(
                spec, next_info.replace(observation=next_info.final.observation, goal=next_info.final.goal))
            episode_return = episode_return + next_info.reward
            finished = next_info.done
            record = dict(observation=observation, raw_action=raw, log_prob=logp, value=value,
                          reward=next_info.reward * cfg.reward_scale, terminated=next_info.terminated,
                          done=finished, final_observation=final_observation,
                          finished_return=jnp.where(finished, episode_return, 0.0), faulted=next_info.faulted)
            episode_return = jnp.where(finished, 0.0, episode_return)
            return (arena_state, next_info, episode_return), record

        key, rollout_key, shuffle_key = jax.random.split(ts.key, 3)
        (arena_state, info, episode_return), batch = jax.lax.scan(
            rollout_step, (ts.arena_state, ts.info, ts.episode_return),
            jax.random.split(rollout_key, cfg.rollout_length))
        stats = ts.observation_stats
        if cfg.normalize_observations:
            stats = normalizer.update(stats, vector_of(batch["observation"]))

        def advantages_of(params, stats, segment):
            """GAE over a (T, ...) time-major segment with the given value network."""
            _, next_values = forward(spec, params, stats, segment["final_observation"])
            return compute_gae(segment["reward"], segment["value"], next_values, segment["terminated"],
                               segment["done"], cfg.discount, cfg.gae_lambda)

        keys = ("observation", "raw_action", "log_prob", "value")
        if unroll is None:
            # GAE once with the acting network; minibatches of single transitions.
            advantages, returns = advantages_of(ts.params, ts.observation_stats, batch)
            samples = dict({k: batch[k] for k in keys}, advantages=advantages, returns=returns)
            samples = jax.tree_util.tree_map(lambda x: x.reshape((cfg.steps_per_update,) + x.shape[2:]), samples)
            sample_axis = 0
        else:
            # (T, B, ...) -> (U, T / U * B, ...): U-step segments, GAE per minibatch with current params.
            samples = {k: batch[k] for k in keys + ("reward", "terminated", "done", "final_observation")}
            samples = jax.tree_util.tree_map(
                lambda x: x.reshape((cfg.rollout_length // unroll, unroll) + x.shape[1:]).swapaxes(0, 1)
                .reshape((unroll, -1) + x.shape[2:]), samples)
            sample_axis = 1
        samples = distributed.replicate(samples)  # on a mesh: gathered once, so each epoch's shuffle is local

        def loss_fn(params, mb):
            policy_out, values = forward(spec, params, stats, mb["observation"])
            if unroll is None:
                advantages, returns = mb["advantages"], mb["returns"]
            else:
                advantages, returns = advantages_of(params, stats, dict(mb, value=values))
            logp = networks.log_prob(spec.action, policy_out, mb["raw_action"])
            terms = ppo_loss(logp, mb["log_prob"], advantages, values, mb["value"], returns,
                             networks.entropy(spec.action, policy_out), clip_epsilon=cfg.clip_epsilon,
                             value_coef=cfg.value_coef, entropy_coef=cfg.entropy_coef,
                             normalize_advantages=unroll is not None)
            return terms.total, terms

        def sgd_step(carry, mb):
            # data parallel over the devices of a mesh (jarena.distributed): each device takes its share of the
            # minibatch, the parameters stay whole on each, and XLA all-reduces the gradients
            if unroll is None:
                # the samples are whole on every device, so the minibatch's advantages are normalised locally;
                # without this hint the partitioner would carry the split below back into the normalisation,
                # and its mean and variance would be two more all-reduces, each waited for, per gradient step
                mb = distributed.replicate(mb)
                mb = dict(mb, advantages=standardized(mb["advantages"]))
            params, opt_state = distributed.replicate(carry)
            grads, terms = jax.grad(loss_fn, has_aux=True)(params, distributed.split_batch(mb, axis=sample_axis))
            updates, opt_state = optimizer().update(grads, opt_state, params)
            return distributed.replicate((optax.apply_updates(params, updates), opt_state)), terms

        def epoch(carry, key):
            count = jax.tree_util.tree_leaves(samples)[0].shape[sample_axis]
            order = jax.random.permutation(key, count)

            def split(x):
                x = jnp.moveaxis(jnp.take(x, order, axis=sample_axis), sample_axis, 0)
                x = x.reshape((cfg.minibatches, count // cfg.minibatches) + x.shape[1:])
                return jnp.moveaxis(x, 1, sample_axis + 1)

            return jax.lax.scan(sgd_step, carry, jax.tree_util.tree_map(split, samples))

        (params, opt_state), terms = jax.lax.scan(epoch, (ts.params, ts.opt_state),
                                                  jax.random.split(shuffle_key, cfg.epochs))
        finished = jnp.sum(batch["done"])
        metrics = dict(episodes=finished,
                       episode_return=jnp.sum(batch["finished_return"]) / jnp.maximum(finished, 1),
                       faulted_episodes=jnp.sum(batch["faulted"]),  # a fault ends its episode
                       **{k: jnp.mean(v) for k, v in dataclasses.asdict(terms).items()})
        ts = PPOTrainState(params=params, opt_state=opt_state, observation_stats=stats, arena_state=arena_state,
                           info=info, episode_return=episode_return, key=key, update=ts.update + 1,
                           env_steps=ts.env_steps + cfg.steps_per_update)
        return ts, metrics

    def train(train_state: PPOTrainState, arena: Arena, num_updates: int):
        """Runs ``num_updates`` updates (static) in one ``lax.scan``; metrics have a leading update axis."""
        return jax.lax.scan(lambda ts, _: one_update(arena, ts), train_state, None, length=num_updates)

    agent = Agent(name="ppo", init=init, act=act, config=dataclasses.asdict(cfg))
    return TrainableAgent.wrap(agent, init_training=init_training, train=train, policy=policy, settings=cfg)


PPOAgent = TrainableAgent  # kept for code written against the first release


register_agent("ppo", make_ppo, tags=("trainable", "rl"))
