"""``dreamer``: DreamerV3's actor-critic, trained in the imagination of a world model learned online.

Collection and the world model are as ``planet``'s (:mod:`jarena_agents.world_model.online`). Each gradient
step trains the model on a window batch, then imagines ``imagination_horizon`` steps from every posterior
state of that batch (their gradients stopped) with the actor, and trains the actor on normalised lambda-returns
with an entropy bonus (by REINFORCE, or through the imagination: below) and the critic (two-hot) on the returns and
on its slow copy
(:mod:`jarena_agents.dreamer.losses`). The actor is DreamerV3's:

- Box actions: a bounded normal: mean ``tanh``, standard deviation in [0.1, 1], samples clipped to [-1, 1] and
  rescaled to the action bounds.
- Discrete(n) actions: a categorical over n classes with 1% of the uniform mixed in ("unimix"), sampled as
  one-hot vectors with straight-through gradients; the world model reads the one-hot vector, the arena the index.

How the actor learns (``actor_gradient``), on advantages normalised by the return scale, with entropy
regularisation 3e-4 (``entropy_coef``):

- ``"reinforce"`` (default): ``logpi * sg(adv)`` for every actor, as DreamerV3's latest version; the imagined
  trajectories and actions are constants of the loss.
- ``"backprop"``: for Box actions, the advantage itself is maximised through the world model's imagination
  (reparameterised action samples, the model's straight-through latent samples, its reward head and the critic),
  as DreamerV3's 2023 version behind its published Control Suite scores (``actor_grad_cont: backprop``); the
  actor reads the states with their gradients stopped, and the model and critic are not changed by this loss.
  Discrete actors learn by REINFORCE either way (``actor_grad_disc: reinforce``).
"""

from __future__ import annotations

import dataclasses
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
from jarena.core.batching import batch_reset
from jarena.core.spec import Discrete
from jarena.core.types import ArenaState, Info
from jarena.data.buffer import make_buffer
from jarena.data.buffer_state import BufferState
from jarena.data.experience import experience_spec
from jarena_agents.config import ConfigError, at_least, in_unit_interval, make_config, non_negative, positive
from jarena_agents.dreamer import losses
from jarena_agents.networks import Gaussian, to_env_action
from jarena_agents.planners.model import is_bounded_continuous
from jarena_agents.registry import register_agent
from jarena_agents.trainable import TrainableAgent
from jarena_agents.world_model import distributions, online
from jarena_agents.world_model import model as wm
from jarena_agents.world_model.networks import Head, Latent, RSSMCell

PyTree = Any
BEHAVIOUR_METRICS = ("actor_loss", "critic_loss", "imagined_return", "return_scale", "actor_entropy")


@dataclasses.dataclass(frozen=True)
class DreamerConfig(online.OnlineConfig):
    """:class:`~jarena_agents.world_model.online.OnlineConfig` plus the actor-critic (DreamerV3's defaults:
    horizon 15, discount 0.997, lambda 0.95, entropy 3e-4, learning rates 3e-5, slow critic rate 0.02)."""

    # H, steps imagined with the actor from every posterior state of the model's batch
    imagination_horizon: int = at_least(1, default=15)
    discount: float = in_unit_interval(0.997, open_low=True)  # gamma of the lambda-returns
    return_lambda: float = in_unit_interval(0.95)  # lambda of the lambda-returns (0: one-step targets, 1: rewards to H)
    # eta, weight of the actor's entropy bonus (advantages are divided by the return scale max(1, P95 - P5))
    entropy_coef: float = non_negative(3e-4)
    actor_learning_rate: float = positive(3e-5)  # Adam's (eps 1e-5), for the actor
    critic_learning_rate: float = positive(3e-5)  # Adam's (eps 1e-5), for the critic
    behaviour_grad_clip: float = positive(100.0)  # global-norm clip of the actor's and of the critic's gradients
    # the slow critic's update after every critic step: slow <- slow + rate (critic - slow)
    slow_critic_rate: float = in_unit_interval(0.02, open_low=True)
    exploration_noise: float = non_negative(0.0)  # the actor samples; no extra noise
    # "reinforce" or "backprop" (Box actions: through the model's imagination, DreamerV3 2023's continuous actors)
    actor_gradient: str = "reinforce"


ACTOR_GRADIENTS = ("reinforce", "backprop")


@struct.dataclass
class Memory:
    """Per-arena acting memory (B, ...): the belief and the previous action (the model's vector)."""

    latent: Latent
    previous_action: jax.Array


@struct.dataclass
class DreamerState:
    """Acting state: model and actor params and, once fitted to a batch (``batch_state``), the memory."""

    params: PyTree  # {"model", "actor"}
    memory: Memory | None
    spec: ArenaSpec = struct.field(pytree_node=False)
    deterministic: bool = struct.field(pytree_node=False, default=False)


@struct.dataclass
class Learner:
    """What gradient steps change: model, actor, critic and slow critic params, optimiser states, return scale."""

    model: PyTree
    actor: PyTree
    critic: PyTree
    slow_critic: PyTree
    model_opt: PyTree
    actor_opt: PyTree
    critic_opt: PyTree
    scale: losses.ReturnScale


@struct.dataclass
class DreamerTrainState:
    """Everything a run needs to continue bit for bit."""

    learner: Learner
    buffer: BufferState
    memory: Memory
    arena_state: ArenaState
    info: Info
    episode_return: jax.Array
    key: jax.Array
    update: jax.Array
    env_steps: jax.Array


def bounded_normal(out: jax.Array) -> Gaussian:
    """DreamerV3's actor distribution from (*, 2 A) outputs: mean ``tanh``, std ``0.1 + 0.9 sigmoid(. + 2)``."""
    mean, std = jnp.split(out, 2, axis=-1)
    return Gaussian(jnp.tanh(mean), jnp.log(0.1 + 0.9 * nn.sigmoid(std + 2.0)))


@struct.dataclass
class OneHotCategorical:
    """DreamerV3's actor distribution for Discrete(n) actions: ``probs`` (*, n), 1% uniform mixed in. Raw
    actions are one-hot vectors (*, n); samples carry straight-through gradients (those of ``probs``)."""

    probs: jax.Array

    def sample(self, key: jax.Array) -> jax.Array:
        return distributions.sample_one_hot(key, self.probs)

    def mode(self) -> jax.Array:
        return distributions.mode_one_hot(self.probs)

    def log_prob(self, one_hot: jax.Array) -> jax.Array:
        """(*): the log-probability of the class each one-hot (*, n) marks."""
        return jnp.sum(jax.lax.stop_gradient(one_hot) * jnp.log(self.probs), -1)

    def entropy(self) -> jax.Array:
        return -jnp.sum(self.probs * jnp.log(self.probs), -1)


def one_hot_categorical(logits: jax.Array) -> OneHotCategorical:
    """The discrete actor's distribution from (*, n) logits, with DreamerV3's 1% unimix."""
    return OneHotCategorical(distributions.categorical_probs(logits, distributions.UNIMIX))


def check_action_spec(spec) -> None:
    """Raises ``ValueError`` unless ``spec`` is Discrete or a float Box with finite bounds."""
    if isinstance(spec, Discrete) or is_bounded_continuous(spec):
        return
    raise ValueError(f"dreamer acts in Discrete or bounded continuous action spaces (a float Box with finite "
                     f"bounds); this arena has {spec!r}")


def actor_outputs(spec) -> int:
    """The actor head's width: ``n`` logits for Discrete(n), a mean and a std per dimension of a Box."""
    return int(spec.n) if isinstance(spec, Discrete) else 2 * int(np.prod(spec.shape, dtype=int))


def actor_distribution(spec, out: jax.Array) -> Gaussian | OneHotCategorical:
    """The actor's distribution for actions of ``spec`` from the head's (*, :func:`actor_outputs`) outputs."""
    return one_hot_categorical(out) if isinstance(spec, Discrete) else bounded_normal(out)


def env_action(spec, raw: jax.Array, dist) -> jax.Array:
    """A raw action (*, n) or (*, A) as the arena takes it: the one-hot's index, or the Box action in bounds."""
    if isinstance(spec, Discrete):
        return jnp.argmax(raw, -1).astype(spec.dtype)
    return to_env_action(spec, raw, dist)


def model_action(spec, raw: jax.Array, dist) -> jax.Array:
    """A raw action (*, ...) as the world model reads it, (*, A): the one-hot itself (straight-through), or
    the Box action in the arena's units (as the buffer holds it), clipped to the bounds: a gradient passes inside
    them and not beyond, where the arena's action no longer changes (DreamerV3's model, fed the unclipped actions
    the arena clipped, learns the same flat response)."""
    if isinstance(spec, Discrete):
        return raw
    return wm.action_vector(spec, to_env_action(spec, raw, dist), raw.ndim - 1)


def make_dreamer(config=None) -> TrainableAgent:
    cfg = make_config(DreamerConfig, config, agent="dreamer")
    cfg = online.check_online_config(cfg, "dreamer")
    if cfg.actor_gradient not in ACTOR_GRADIENTS:
        raise ConfigError(f"config key 'actor_gradient' of agent 'dreamer' must be one of {list(ACTOR_GRADIENTS)}, "
                          f"got {cfg.actor_gradient!r}")
    model_cfg = cfg.model_config()
    compute = wm.compute_dtype(model_cfg, "dreamer")
    buffer = make_buffer(cfg.num_arenas, cfg.buffer_size, cfg.batch_size, mode="window", length=cfg.sequence_length)
    model_opt = wm.model_optimizer(model_cfg)
    actor_opt = optax.chain(wm.clip_by_flat_global_norm(cfg.behaviour_grad_clip),
                            optax.adam(cfg.actor_learning_rate, eps=1e-5))
    critic_opt = optax.chain(wm.clip_by_flat_global_norm(cfg.behaviour_grad_clip),
                             optax.adam(cfg.critic_learning_rate, eps=1e-5))

    def world_model(spec: ArenaSpec) -> wm.WorldModel:
        check_action_spec(spec.action)
        return wm.make_world_model(spec, model_cfg)

    def actor(spec: ArenaSpec) -> Head:
        check_action_spec(spec.action)
        # a discrete actor starts uniform (zero logits), as DreamerV3's nearly does (output scale 0.01)
        return Head(actor_outputs(spec.action), cfg.hidden, cfg.layers, zero_init=isinstance(spec.action, Discrete),
                    dtype=compute)

    def critic() -> Head:
        return Head(cfg.bins, cfg.hidden, cfg.layers, zero_init=True, dtype=compute)

    def fresh_memory(spec: ArenaSpec, num_arenas: int) -> Memory:
        model = world_model(spec)
        return Memory(latent=model.initial((num_arenas,)),
                      previous_action=jnp.zeros((num_arenas, model.action_size), jnp.float32))

    def init_params(key, spec: ArenaSpec) -> dict:
        model_key, actor_key, critic_key = jax.random.split(key, 3)
        model = world_model(spec)
        features = model.initial((1,)).features()
        return {"model": wm.init_params(model, model_key), "actor": actor(spec).init(actor_key, features),
                "critic": critic().init(critic_key, features)}

    def init(key, spec: ArenaSpec, num_arenas: int) -> DreamerState:
        params = init_params(key, spec)
        return DreamerState(params={"model": params["model"], "actor": params["actor"]},
                            memory=fresh_memory(spec, num_arenas), spec=spec)

    def batch_state(state: DreamerState, num_arenas: int) -> DreamerState:
        if state.memory is not None and state.memory.previous_action.shape[0] == num_arenas:
            return state
        return state.replace(memory=fresh_memory(state.spec, num_arenas))

    def reset(state: DreamerState, mask) -> DreamerState:
        return state.replace(memory=online.restart(mask, fresh_memory(state.spec, mask.shape[0]), state.memory))

    def choose(spec: ArenaSpec, params: dict, memory: Memory, info: Info, key, deterministic: bool):
        model = world_model(spec)
        latent = online.filter_belief(model, params["model"], memory.latent, memory.previous_action, info)
        policy = actor_distribution(spec.action, actor(spec).apply(params["actor"], latent.features()))
        action = env_action(spec.action, policy.mode() if deterministic else policy.sample(key), policy)
        return action, Memory(latent=latent, previous_action=wm.action_vector(spec.action, action, 1))

    def act(state: DreamerState, info: Info, key, privileged=None):
        decide = lambda memory, info: choose(state.spec, state.params, memory, info, key, state.deterministic)
        action, memory = online.hold_between_decisions(cfg.action_repeat, state.spec.action, info, state.memory,
                                                       decide)
        return action, state.replace(memory=memory)

    def policy(train_state: DreamerTrainState, spec: ArenaSpec, deterministic: bool = True) -> DreamerState:
        """The acting state of a trained agent; its memory is allocated for the runner's batch."""
        params = {"model": train_state.learner.model, "actor": train_state.learner.actor}
        return DreamerState(params=params, memory=None, spec=spec, deterministic=deterministic)

    def init_training(key, arena: Arena) -> DreamerTrainState:
        arena = online.decision_arena(arena, cfg.action_repeat)
        spec = arena.spec
        key, params_key, reset_key = jax.random.split(key, 3)
        params = init_params(params_key, spec)
        learner = Learner(model=params["model"], actor=params["actor"], critic=params["critic"],
                          slow_critic=jax.tree_util.tree_map(jnp.copy, params["critic"]),
                          model_opt=model_opt.init(params["model"]), actor_opt=actor_opt.init(params["actor"]),
                          critic_opt=critic_opt.init(params["critic"]), scale=losses.ReturnScale.create())
        arena_state, info = batch_reset(arena, reset_key, cfg.num_arenas)
        return DreamerTrainState(learner=learner, buffer=buffer.init(experience_spec(arena)),
                                 memory=fresh_memory(spec, cfg.num_arenas), arena_state=arena_state, info=info,
                                 episode_return=jnp.zeros((cfg.num_arenas,), jnp.float32), key=key,
                                 update=jnp.zeros((), jnp.int32), env_steps=jnp.zeros((), jnp.int32))

    def behaviour_step(spec: ArenaSpec, learner: Learner, starts: Latent, key):
        """Imagines from ``starts`` (flattened (N,)) and takes one actor and one critic step."""
        model = world_model(spec)
        net = actor(spec)
        keys = jax.random.split(key, cfg.imagination_horizon)
        backprop = cfg.actor_gradient == "backprop" and not isinstance(spec.action, Discrete)

        def imagine(actor_params):
            """The imagined trajectory (H + 1, N) from ``starts`` and the raw actions (H, N, A); the actor reads
            each state with its gradient stopped, so a gradient reaches it through its actions alone."""
            def step(latent, key):
                action_key, model_key = jax.random.split(key)
                out = net.apply(actor_params, jax.lax.stop_gradient(latent.features()))
                dist = actor_distribution(spec.action, out)
                raw = dist.sample(action_key)
                following, _ = model.rssm.apply(learner.model["rssm"], latent, model_action(spec.action, raw, dist),
                                                model_key, method=RSSMCell.img_step)
                return following, (latent, raw)

            last, (latents, raws) = jax.lax.scan(step, starts, keys, unroll=cfg.scan_unroll)
            return jax.tree_util.tree_map(lambda xs, x: jnp.concatenate([xs, x[None]], 0), latents, last), raws

        def score(trajectory: Latent):
            """The critic's values (H + 1, N) of ``trajectory``, and its lambda-returns (H, N) and weights (H, N)
            from the model's rewards and continuation probabilities."""
            rewards = wm.predict_reward(model, learner.model, trajectory)
            continues = wm.continue_probability(model, learner.model, trajectory)
            values = distributions.two_hot_mean(critic().apply(learner.critic, trajectory.features()), model.centres)
            returns = losses.lambda_returns(rewards, continues, values, cfg.discount, cfg.return_lambda,
                                            cfg.scan_unroll)
            return values, returns, losses.trajectory_weights(continues, cfg.discount)

        if backprop:
            def actor_objective(params):
                trajectory, _ = imagine(params)
                values, returns, weights = score(trajectory)
                scale = learner.scale.update(jax.lax.stop_gradient(returns))
                dist = actor_distribution(spec.action,
                                          net.apply(params, jax.lax.stop_gradient(trajectory.features()[:-1])))
                loss = losses.backprop_actor_loss(dist.entropy(), returns, values[:-1], weights, scale.scale,
                                                  cfg.entropy_coef)
                return loss, (jnp.mean(dist.entropy()), jax.lax.stop_gradient((trajectory, returns, weights, scale)))

            (actor_value, (entropy, kept)), grads = jax.value_and_grad(actor_objective, has_aux=True)(learner.actor)
            trajectory, returns, weights, scale = kept
            features = trajectory.features()
        else:  # REINFORCE: the imagined trajectory (H + 1, N) and its actions (H, N, A) are constants
            trajectory, raws = jax.lax.stop_gradient(imagine(learner.actor))
            features = trajectory.features()
            values, returns, weights = score(trajectory)
            scale = learner.scale.update(returns)

            def actor_objective(params):
                dist = actor_distribution(spec.action, net.apply(params, features[:-1]))
                return losses.actor_loss(dist.log_prob(raws), dist.entropy(), returns, values[:-1], weights,
                                         scale.scale, cfg.entropy_coef), jnp.mean(dist.entropy())

            (actor_value, entropy), grads = jax.value_and_grad(actor_objective, has_aux=True)(learner.actor)
        slow_values = distributions.two_hot_mean(critic().apply(learner.slow_critic, features), model.centres)
        updates, actor_state = actor_opt.update(grads, learner.actor_opt, learner.actor)
        actor_params = optax.apply_updates(learner.actor, updates)

        def critic_objective(params):
            logits = critic().apply(params, features[:-1])
            return losses.critic_loss(logits, returns, slow_values[:-1], weights, model.centres)

        critic_value, grads = jax.value_and_grad(critic_objective)(learner.critic)
        updates, critic_state = critic_opt.update(grads, learner.critic_opt, learner.critic)
        critic_params = optax.apply_updates(learner.critic, updates)
        learner = learner.replace(actor=actor_params, critic=critic_params, actor_opt=actor_state,
                                  critic_opt=critic_state, scale=scale,
                                  slow_critic=losses.ema(learner.slow_critic, critic_params, cfg.slow_critic_rate))
        metrics = dict(actor_loss=actor_value, critic_loss=critic_value, imagined_return=jnp.mean(returns[0]),
                       return_scale=scale.scale, actor_entropy=entropy)
        return learner, metrics

    def one_update(arena: Arena, ts: DreamerTrainState):
        spec = arena.spec
        model = world_model(spec)
        key, rollout_key, learn_key = jax.random.split(ts.key, 3)
        params = {"model": ts.learner.model, "actor": ts.learner.actor}
        act_fn = lambda memory, info, k: choose(spec, params, memory, info, k, False)
        running = online.Collection(ts.arena_state, ts.info, ts.episode_return, ts.buffer, ts.memory)
        running, record = online.collect(arena, cfg, buffer, running, ts.env_steps, act_fn, rollout_key)
        env_steps = ts.env_steps + cfg.steps_per_update

        def gradient_step(learner: Learner, key):
            model_key, behaviour_key = jax.random.split(key)
            learner = distributed.replicate(learner)  # on a mesh: the networks whole on each device
            model_params, model_state, model_metrics, latents = online.model_step(
                model, model_opt, buffer, running.buffer, learner.model, learner.model_opt, model_key)
            learner = learner.replace(model=model_params, model_opt=model_state)
            starts = jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[2:]), latents)
            starts = distributed.split_batch(jax.lax.stop_gradient(starts))  # each device imagines from its share
            learner, behaviour_metrics = behaviour_step(spec, learner, starts, behaviour_key)
            return distributed.replicate(learner), {**model_metrics, **behaviour_metrics}

        ready = (env_steps >= cfg.learning_starts) & buffer.can_sample(running.buffer)
        learner, metrics = online.learn_when_ready(ready, gradient_step, ts.learner, learn_key, cfg.gradient_steps,
                                                   online.MODEL_METRICS + BEHAVIOUR_METRICS)
        ts = DreamerTrainState(learner=learner, buffer=running.buffer, memory=running.memory,
                               arena_state=running.arena_state, info=running.info,
                               episode_return=running.episode_return, key=key, update=ts.update + 1,
                               env_steps=env_steps)
        return ts, {**online.episode_metrics(record, running.episode_return), **metrics}

    def train(train_state: DreamerTrainState, arena: Arena, num_updates: int):
        """Runs ``num_updates`` updates (static) in one ``lax.scan``; metrics have a leading update axis."""
        arena = online.decision_arena(arena, cfg.action_repeat)
        return jax.lax.scan(lambda ts, _: one_update(arena, ts), train_state, None, length=num_updates)

    agent = Agent(name="dreamer", init=init, act=act, reset=reset, batch_state=batch_state,
                  config=dataclasses.asdict(cfg))
    return TrainableAgent.wrap(agent, init_training=init_training, train=train, policy=policy, settings=cfg)


register_agent("dreamer", make_dreamer, tags=("trainable", "world-model"))
