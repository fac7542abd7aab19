"""``planet``: a world model learned online or from a dataset, and CEM planning in its latent space (Hafner et al.
2019, PlaNet).

Online (``dataset`` empty, the default), each update collects ``rollout_length`` steps of the B arenas into a
window buffer (:mod:`jarena_agents.world_model.online`), then takes ``gradient_steps`` world-model gradient steps
(``train_steps``, or as many as ``replay_ratio`` asks; :mod:`jarena_agents.world_model`) on sequences of
``sequence_length`` transitions. Until ``learning_starts`` environment steps, actions are uniform (the seed
episodes); afterwards the agent acts as below, with Gaussian exploration noise.

Offline (``dataset`` set to the path of a :class:`~jarena.data.TrajectoryDataset`, e.g. one written by ``jarena
collect``), the model learns from the dataset's trajectories alone, as PlaNet-ClothPick does on cloth
(:mod:`jarena_agents.planet.offline`): no arena is stepped while training, each update is one gradient step on
``batch_size`` windows of ``sequence_length`` transitions of one trajectory, and ``total_steps`` counts gradient
updates (:class:`~jarena_agents.config.DatasetSchedule`); ``augment`` may turn the windows. The collection keys
(``num_arenas``, ``rollout_length``, ``train_steps``, ``replay_ratio``, ``buffer_size``, ``learning_starts``) are
not used.

Acting (either way): per arena, the belief is filtered with each observation and the previous action (restarted at
a new episode), then CEM (:func:`jarena_agents.planners.cem.cem_improve`) plans ``horizon`` actions over
:func:`jarena_agents.world_model.model.latent_model` -- the same planner code that plans over an arena's own
dynamics -- warm-started from the previous plan shifted by one step. Defaults: PlaNet's planner (horizon 12, 1000
candidates, 100 elites, 10 iterations), exploration noise 0.3.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from jarena.core.agent import Agent
from jarena.core.arena import Arena, ArenaSpec
from jarena.core.batching import batch_reset
from jarena.core.types import ArenaState, Info
from jarena.data.buffer import make_buffer
from jarena.data.buffer_state import BufferState
from jarena.data.experience import experience_spec
from jarena_agents.config import DatasetSchedule, at_least, in_unit_interval, make_config
from jarena_agents.planet import offline
from jarena_agents.planners.cem import CEMConfig, cem_improve
from jarena_agents.planners.model import is_bounded_continuous
from jarena_agents.planners.sampling import shift_plan
from jarena_agents.registry import register_agent
from jarena_agents.trainable import TrainableAgent
from jarena_agents.world_model import model as wm
from jarena_agents.world_model import online
from jarena_agents.world_model.networks import Latent

PyTree = Any


@dataclasses.dataclass(frozen=True)
class PlaNetConfig(online.OnlineConfig):
    """:class:`~jarena_agents.world_model.online.OnlineConfig` (model, collection) plus the planner, and the dataset
    of offline training."""

    # a TrajectoryDataset's path: set, the model learns from its trajectories alone (offline; total_steps then counts
    # gradient updates); empty, online from the arenas
    dataset: str = ""
    augment: str = "none"  # offline: "rotate90" turns each window and its image-point actions by quarter turns
    horizon: int = at_least(1, default=12)  # H, plan length in agent steps, in the latent model (PlaNet's 12)
    samples: int = at_least(1, default=1000)  # plans per CEM iteration, the current mean among them (PlaNet's 1000)
    iterations: int = at_least(1, default=10)  # CEM iterations per act (PlaNet's 10)
    elite_fraction: float = in_unit_interval(0.1, open_low=True)  # share kept as elites, at least 1 (PlaNet's 100)

    @property
    def steps_per_update(self) -> int:
        """Offline, 1 (an update is a gradient step, :class:`DatasetSchedule`); online, the arenas' steps per update."""
        return DatasetSchedule.steps_per_update.fget(self) if self.dataset else super().steps_per_update

    @property
    def num_updates(self) -> int:
        return DatasetSchedule.num_updates.fget(self) if self.dataset else super().num_updates

    @property
    def step_unit(self) -> str:
        """What ``total_steps`` counts (the ``jarena train`` command prints it)."""
        return DatasetSchedule.step_unit.fget(self) if self.dataset else "environment steps"


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


def check_action_spec(spec) -> None:
    """Raises ``ValueError`` unless ``spec`` is a float Box with finite bounds: CEM samples and clips plans in it."""
    if is_bounded_continuous(spec):
        return
    raise ValueError(f"planet plans with CEM over continuous actions and needs a bounded continuous action spec "
                     f"(a float Box with finite bounds); this arena has {spec!r} (dreamer takes Discrete actions)")


def make_planet(config=None) -> TrainableAgent:
    cfg = make_config(PlaNetConfig, config, agent="planet")
    offline.check_augment(cfg.augment)
    if cfg.dataset and cfg.action_repeat != 1:
        raise ValueError(f"planet: action_repeat={cfg.action_repeat} holds actions while collecting online; a dataset "
                         f"({cfg.dataset!r}) holds the transitions as collected: use action_repeat=1 (and collect "
                         f"the dataset on an arena with action:repeat(n) for longer decisions)")
    cfg = cfg if cfg.dataset else online.check_online_config(cfg, "planet")
    model_cfg = cfg.model_config()
    cem = CEMConfig(samples=cfg.samples, horizon=cfg.horizon, iterations=cfg.iterations,
                    elite_fraction=cfg.elite_fraction, noise=1.0)
    buffer = None if cfg.dataset else make_buffer(cfg.num_arenas, cfg.buffer_size, cfg.batch_size, mode="window",
                                                  length=cfg.sequence_length)
    optimizer = wm.model_optimizer(model_cfg)

    def world_model(spec: ArenaSpec) -> wm.WorldModel:
        check_action_spec(spec.action)
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
        return state.replace(memory=online.restart(mask, fresh_memory(state.spec, mask.shape[0]), state.memory))

    def plan_actions(spec: ArenaSpec, params, memory: Memory, info: Info, key, noise: float):
        """Filters the belief with ``info``'s observations and plans: ``(actions (B, ...), memory)``."""
        model = world_model(spec)
        first = info.step == 0
        plan = online.restart(first, jnp.zeros_like(memory.plan), memory.plan)
        latent = online.filter_belief(model, params, memory.latent, memory.previous_action, info)
        improve = cem_improve(wm.latent_model(model, params, "planet"), cem)
        plan_key, noise_key = jax.random.split(key)
        plans = jax.vmap(improve)(latent, plan, jax.random.split(plan_key, first.shape[0]))
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
        decide = lambda memory, info: plan_actions(state.spec, state.params, memory, info, key, noise)
        action, memory = online.hold_between_decisions(cfg.action_repeat, state.spec.action, info, state.memory,
                                                       decide)
        return action, state.replace(memory=memory)

    def policy(train_state, spec: ArenaSpec, deterministic: bool = True) -> PlaNetState:
        """The acting state of a trained agent (online or offline); its memory is allocated for the runner's
        batch."""
        return PlaNetState(params=train_state.params, memory=None, spec=spec, deterministic=deterministic)

    def init_training(key, arena: Arena) -> PlaNetTrainState:
        arena = online.decision_arena(arena, cfg.action_repeat)
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
        model = world_model(arena.spec)
        key, rollout_key, learn_key = jax.random.split(ts.key, 3)
        choose = lambda memory, info, k: plan_actions(arena.spec, ts.params, memory, info, k, cfg.exploration_noise)
        running = online.Collection(ts.arena_state, ts.info, ts.episode_return, ts.buffer, ts.memory)
        running, record = online.collect(arena, cfg, buffer, running, ts.env_steps, choose, rollout_key)
        env_steps = ts.env_steps + cfg.steps_per_update

        def gradient_step(carry, key):
            params, opt_state, metrics, _ = online.model_step(model, optimizer, buffer, running.buffer, *carry, key)
            return (params, opt_state), metrics

        ready = (env_steps >= cfg.learning_starts) & buffer.can_sample(running.buffer)
        (params, opt_state), metrics = online.learn_when_ready(ready, gradient_step, (ts.params, ts.opt_state),
                                                               learn_key, cfg.gradient_steps, online.MODEL_METRICS)
        ts = PlaNetTrainState(params=params, opt_state=opt_state, buffer=running.buffer, memory=running.memory,
                              arena_state=running.arena_state, info=running.info,
                              episode_return=running.episode_return, key=key, update=ts.update + 1,
                              env_steps=env_steps)
        return ts, {**online.episode_metrics(record, running.episode_return), **metrics}

    def train(train_state: PlaNetTrainState, arena: Arena, num_updates: int):
        """Runs ``num_updates`` updates (static) in one ``lax.scan``; metrics have a leading update axis."""
        arena = online.decision_arena(arena, cfg.action_repeat)
        return jax.lax.scan(lambda ts, _: one_update(arena, ts), train_state, None, length=num_updates)

    def init_offline_training(key, arena: Arena) -> offline.OfflineTrainState:
        return offline.init_training(cfg, world_model(arena.spec), optimizer, key, arena)

    def train_offline(train_state: offline.OfflineTrainState, arena: Arena, num_updates: int):
        """Runs ``num_updates`` gradient steps (static) on the dataset in one ``lax.scan``; the arena is not
        stepped (its spec shapes the model); metrics have a leading update axis."""
        model = world_model(arena.spec)
        return jax.lax.scan(lambda ts, _: offline.update(cfg, model, optimizer, ts), train_state, None,
                            length=num_updates)

    if cfg.dataset:
        init_training, train = init_offline_training, train_offline

    agent = Agent(name="planet", init=init, act=act, reset=reset, batch_state=batch_state,
                  config=dataclasses.asdict(cfg))
    return TrainableAgent.wrap(agent, init_training=init_training, train=train, policy=policy, settings=cfg)


register_agent("planet", make_planet, tags=("trainable", "world-model"))
