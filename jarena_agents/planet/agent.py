"""``planet``: a world model learned online, and CEM planning in its latent space (Hafner et al. 2019, PlaNet).

Each update steps the B arenas ``rollout_length`` times and adds the transitions to a window buffer; then
``train_steps`` world-model gradient steps (:mod:`jarena_agents.world_model`) on sequences of
``sequence_length`` transitions. Until ``learning_starts`` environment steps, actions are uniform (the
seed episodes); afterwards the agent acts as below, with Gaussian exploration noise.

Acting: per arena, the belief ``Latent`` is filtered with each observation and the previous action (the
posterior's mode; it restarts at a new episode), then CEM (:func:`jarena_agents.planners.cem.cem_improve`)
plans ``horizon`` actions over :func:`jarena_agents.world_model.model.latent_model` -- the same planner code
that plans over an arena's own dynamics -- warm-started from the previous plan shifted by one step.
Defaults: PlaNet's planner (horizon 12, 1000 candidates, 100 elites, 10 iterations), exploration noise 0.3.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from jarena.core.agent import Agent
from jarena.core.arena import Arena, ArenaSpec
from jarena.core.batching import batch_reset, batch_step
from jarena.core.types import ArenaState, Info
from jarena.data.buffer import make_buffer
from jarena.data.buffer_state import BufferState
from jarena.data.experience import experience_spec, transition_from
from jarena_agents.config import at_least, in_unit_interval, make_config, non_negative
from jarena_agents.planners.cem import CEMConfig, cem_improve
from jarena_agents.planners.model import check_action_spec
from jarena_agents.planners.sampling import shift_plan
from jarena_agents.registry import register_agent
from jarena_agents.trainable import TrainableAgent
from jarena_agents.world_model import model as wm
from jarena_agents.world_model.model import WorldModelConfig
from jarena_agents.world_model.networks import Latent, RSSMCell

PyTree = Any


@dataclasses.dataclass(frozen=True)
class PlaNetConfig(WorldModelConfig):
    """:class:`WorldModelConfig` (the model) plus data collection and planning."""

    num_arenas: int = at_least(1, default=8)
    rollout_length: int = at_least(1, default=100)  # environment steps per arena per update
    train_steps: int = at_least(1, default=100)  # world-model gradient steps per update
    batch_size: int = at_least(1, default=16)
    sequence_length: int = at_least(2, default=50)
    buffer_size: int = at_least(1, default=1_000_000)
    learning_starts: int = at_least(0, default=5_000)  # environment steps of uniform actions first
    total_steps: int = at_least(1, default=1_000_000)
    horizon: int = at_least(1, default=12)
    samples: int = at_least(1, default=1000)
    iterations: int = at_least(1, default=10)
    elite_fraction: float = in_unit_interval(0.1, open_low=True)
    exploration_noise: float = non_negative(0.3)  # fraction of the action half-range

    @property
    def steps_per_update(self) -> int:
        return self.num_arenas * self.rollout_length

    @property
    def num_updates(self) -> int:
        return max(1, self.total_steps // self.steps_per_update)


@struct.dataclass
class Memory:
    """Per-arena acting memory (B, ...): the belief, the previous action (the model's vector) and the plan."""

    latent: Latent
    previous_action: jax.Array  # float32 (B, A)
    plan: jax.Array  # float32 (B, H, *action_shape)


@struct.dataclass
class PlaNetState:
    """Acting state: the world model's params and, once fitted to a batch (``batch_state``), the memory."""

    params: PyTree
    memory: Memory | None
    spec: ArenaSpec = struct.field(pytree_node=False)
    deterministic: bool = struct.field(pytree_node=False, default=False)


@struct.dataclass
class PlaNetTrainState:
    """Everything a run needs to continue bit for bit (model, optimiser, buffer, arenas, memory, RNG)."""

    params: PyTree
    opt_state: PyTree
    buffer: BufferState
    memory: Memory
    arena_state: ArenaState
    info: Info
    episode_return: jax.Array  # (B,)
    key: jax.Array
    update: jax.Array  # int32
    env_steps: jax.Array  # int32


METRICS = ("model_loss", "observation_loss", "reward_loss", "continue_loss", "kl")


def _check_config(cfg: PlaNetConfig) -> None:
    if cfg.buffer_size % cfg.num_arenas:
        raise ValueError(f"planet: buffer_size={cfg.buffer_size} must be a multiple of num_arenas={cfg.num_arenas}")
    if cfg.buffer_size // cfg.num_arenas < cfg.sequence_length:
        raise ValueError(f"planet: each arena keeps buffer_size / num_arenas = {cfg.buffer_size // cfg.num_arenas} "
                         f"steps, fewer than sequence_length={cfg.sequence_length}")


def make_planet(config=None) -> TrainableAgent:
    cfg = make_config(PlaNetConfig, config, agent="planet")
    _check_config(cfg)
    model_cfg = WorldModelConfig(**{f.name: getattr(cfg, f.name) for f in dataclasses.fields(WorldModelConfig)})
    cem = CEMConfig(samples=cfg.samples, horizon=cfg.horizon, iterations=cfg.iterations,
                    elite_fraction=cfg.elite_fraction, noise=1.0)
    buffer = make_buffer(cfg.num_arenas, cfg.buffer_size, cfg.batch_size, mode="window", length=cfg.sequence_length)
    optimizer = wm.model_optimizer(model_cfg)

    def world_model(spec: ArenaSpec) -> wm.WorldModel:
        check_action_spec(spec.action, "planet")
        return wm.make_world_model(spec, model_cfg)

    def fresh_memory(spec: ArenaSpec, num_arenas: int) -> Memory:
        model = world_model(spec)
        return Memory(latent=model.initial((num_arenas,)),
                      previous_action=jnp.zeros((num_arenas, model.action_size), jnp.float32),
                      plan=jnp.zeros((num_arenas, cfg.horizon) + tuple(spec.action.shape), jnp.float32))

    def init(key, spec: ArenaSpec, num_arenas: int) -> PlaNetState:
        params = wm.init_params(world_model(spec), key)
        return PlaNetState(params=params, memory=fresh_memory(spec, num_arenas), spec=spec)

    def batch_state(state: PlaNetState, num_arenas: int) -> PlaNetState:
        if state.memory is not None and state.memory.plan.shape[0] == num_arenas:
            return state
        return state.replace(memory=fresh_memory(state.spec, num_arenas))

    def reset(state: PlaNetState, mask) -> PlaNetState:
        fresh = fresh_memory(state.spec, mask.shape[0])
        keep = lambda new, old: jnp.where(mask.reshape((-1,) + (1,) * (old.ndim - 1)), new, old)
        return state.replace(memory=jax.tree_util.tree_map(keep, fresh, state.memory))

    def plan_actions(spec: ArenaSpec, params, memory: Memory, info: Info, key, noise: float):
        """Filters the belief with ``info``'s observations and plans: ``(actions (B, ...), memory)``."""
        model = world_model(spec)
        first = info.step == 0
        fresh = fresh_memory(spec, first.shape[0])
        memory = jax.tree_util.tree_map(
            lambda new, old: jnp.where(first.reshape((-1,) + (1,) * (old.ndim - 1)), new, old), fresh, memory)
        vector, images = _observation(model, info)
        embed = model.encoder.apply(params["encoder"], vector, images)
        latent, _, _ = model.rssm.apply(params["rssm"], memory.latent, memory.previous_action, embed, None,
                                        method=RSSMCell.obs_step)
        improve = cem_improve(wm.latent_model(model, params, "planet"), cem)
        plan_key, noise_key = jax.random.split(key)
        plans = jax.vmap(improve)(latent, memory.plan, jax.random.split(plan_key, first.shape[0]))
        low = jnp.asarray(spec.action.low, jnp.float32)
        high = jnp.asarray(spec.action.high, jnp.float32)
        action = plans[:, 0]
        if noise:
            action = action + noise * (high - low) / 2 * jax.random.normal(noise_key, action.shape)
        action = jnp.clip(action, low, high)
        shifted = jax.vmap(lambda p: shift_plan(p, p[-1]))(plans)  # warm start: padded with its last action
        memory = Memory(latent=latent, previous_action=wm.action_vector(spec.action, action, 1), plan=shifted)
        return action.astype(spec.action.dtype), memory

    def act(state: PlaNetState, info: Info, key, privileged=None):
        noise = 0.0 if state.deterministic else cfg.exploration_noise
        action, memory = plan_actions(state.spec, state.params, state.memory, info, key, noise)
        return action, state.replace(memory=memory)

    def policy(train_state: PlaNetTrainState, spec: ArenaSpec, deterministic: bool = True) -> PlaNetState:
        """The acting state of a trained agent; its memory is allocated for the runner's batch."""
        return PlaNetState(params=train_state.params, memory=None, spec=spec, deterministic=deterministic)

    def init_training(key, arena: Arena) -> PlaNetTrainState:
        spec = arena.spec
        key, model_key, reset_key = jax.random.split(key, 3)
        params = wm.init_params(world_model(spec), model_key)
        arena_state, info = batch_reset(arena, reset_key, cfg.num_arenas)
        return PlaNetTrainState(params=params, opt_state=optimizer.init(params),
                                buffer=buffer.init(experience_spec(arena)), memory=fresh_memory(spec, cfg.num_arenas),
                                arena_state=arena_state, info=info,
                                episode_return=jnp.zeros((cfg.num_arenas,), jnp.float32), key=key,
                                update=jnp.zeros((), jnp.int32), env_steps=jnp.zeros((), jnp.int32))

    def one_update(arena: Arena, ts: PlaNetTrainState):
        spec = arena.spec
        model = world_model(spec)
        arena_params = arena.default_params()

        def env_step(carry, xs):
            arena_state, info, episode_return, buffer_state, memory = carry
            index, key = xs
            plan_key, random_key = jax.random.split(key)
            planned, planned_memory = plan_actions(spec, ts.params, memory, info, plan_key, cfg.exploration_noise)
            seeding = ts.env_steps + index * cfg.num_arenas < cfg.learning_starts
            uniform = jax.vmap(spec.action.sample)(jax.random.split(random_key, cfg.num_arenas))
            action = jnp.where(seeding, uniform, planned)
            memory = planned_memory.replace(previous_action=wm.action_vector(spec.action, action, 1))
            arena_state, next_info = batch_step(arena, arena_state, action, arena_params)
            buffer_state = buffer.add(buffer_state, transition_from(info, action, next_info))
            episode_return = episode_return + next_info.reward
            finished = next_info.done
            record = dict(done=finished, finished_return=jnp.where(finished, episode_return, 0.0),
                          faulted=next_info.faulted)
            episode_return = jnp.where(finished, 0.0, episode_return)
            return (arena_state, next_info, episode_return, buffer_state, memory), record

        key, rollout_key, learn_key = jax.random.split(ts.key, 3)
        carry = (ts.arena_state, ts.info, ts.episode_return, ts.buffer, ts.memory)
        (arena_state, info, episode_return, buffer_state, memory), record = jax.lax.scan(
            env_step, carry,
            (jnp.arange(cfg.rollout_length, dtype=jnp.int32), jax.random.split(rollout_key, cfg.rollout_length)))
        env_steps = ts.env_steps + cfg.steps_per_update

        def gradient_step(carry, key):
            params, opt_state = carry
            sample_key, loss_key = jax.random.split(key)
            seq = wm.sequences_from_windows(spec, buffer.sample(buffer_state, sample_key).experience)
            params, opt_state, metrics = wm.train_step(model, optimizer, params, opt_state, seq, loss_key)
            return (params, opt_state), {k: metrics[k] for k in METRICS}

        def learn(carry):
            carry, metrics = jax.lax.scan(gradient_step, carry, jax.random.split(learn_key, cfg.train_steps))
            return carry, {k: jnp.mean(v) for k, v in metrics.items()}

        def wait(carry):
            return carry, {k: jnp.zeros((), jnp.float32) for k in METRICS}

        ready = (env_steps >= cfg.learning_starts) & buffer.can_sample(buffer_state)
        (params, opt_state), metrics = jax.lax.cond(ready, learn, wait, (ts.params, ts.opt_state))
        finished = jnp.sum(record["done"])
        metrics = dict(episodes=finished, episode_return=jnp.sum(record["finished_return"]) / jnp.maximum(finished, 1),
                       faulted_episodes=jnp.sum(record["faulted"]), **metrics)
        ts = PlaNetTrainState(params=params, opt_state=opt_state, buffer=buffer_state, memory=memory,
                              arena_state=arena_state, info=info, episode_return=episode_return, key=key,
                              update=ts.update + 1, env_steps=env_steps)
        return ts, metrics

    def train(train_state: PlaNetTrainState, arena: Arena, num_updates: int):
        """Runs ``num_updates`` updates (static) in one ``lax.scan``; metrics have a leading update axis."""
        return jax.lax.scan(lambda ts, _: one_update(arena, ts), train_state, None, length=num_updates)

    agent = Agent(name="planet", init=init, act=act, reset=reset, batch_state=batch_state,
                  config=dataclasses.asdict(cfg))
    return TrainableAgent.wrap(agent, init_training=init_training, train=train, policy=policy, settings=cfg)


def _observation(model: wm.WorldModel, info: Info):
    """``(vector (B, D), images {key: (B, H, W, C)})`` laid out as :func:`wm.sequences_from_windows` does."""
    rest = {k: v for k, v in info.observation.items() if k not in model.images}
    leaves = jax.tree_util.tree_leaves(rest) + [info.goal]
    batch = info.reward.shape[0]
    vector = jnp.concatenate([x.reshape((batch, -1)).astype(jnp.float32) for x in leaves], -1)
    return vector, {k: info.observation[k] for k in model.images}


register_agent("planet", make_planet, tags=("trainable", "world-model"))
