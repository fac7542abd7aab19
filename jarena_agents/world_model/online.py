"""What every agent that learns a world model online shares (``planet``, ``dreamer``): the collection settings,
the belief filter, the collection rollout into a window buffer, and one model gradient step.

Each update steps the B arenas ``rollout_length`` times, adding the transitions to the buffer; until
``learning_starts`` environment steps the actions are uniform (the seed episodes), then the agent's own. The
belief of each arena is the posterior's mode given its observations and previous actions, restarted where a new
episode begins (``info.step == 0``).

With ``action_repeat`` k > 1 the agent decides every k-th environment step and holds its action in between,
rewards summed over the k steps, as DreamerV3 and PlaNet run the Control Suite (their environment wrappers'
action repeat): training steps the arena through a ``repeat(k)`` action tool (:func:`decision_arena`), acting
(:func:`hold_between_decisions`) decides where ``info.step`` is a multiple of k and repeats the held action
elsewhere, so the agent runs on the arena as given, counted in its environment steps.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from jarena import distributed, tools
from jarena.core.arena import Arena
from jarena.core.batching import batch_step
from jarena.core.spec import Discrete
from jarena.core.tool import ActionTool
from jarena.core.types import Info
from jarena.data.experience import transition_from
from jarena_agents import networks
from jarena_agents.config import ArenaSchedule, at_least, non_negative, positive, rounded_buffer
from jarena_agents.world_model import model as wm
from jarena_agents.world_model.model import WorldModelConfig
from jarena_agents.world_model.networks import Latent, RSSMCell

PyTree = Any
MODEL_METRICS = ("model_loss", "observation_loss", "reward_loss", "continue_loss", "kl")


@dataclasses.dataclass(frozen=True)
class OnlineConfig(WorldModelConfig, ArenaSchedule):
    """:class:`WorldModelConfig` plus data collection and model training."""

    num_arenas: int = at_least(1, default=8)  # arenas stepped together, each keeping its own part of the buffer
    rollout_length: int = at_least(1, default=100)  # decisions per arena per update
    # environment steps each decision's action is held for, rewards summed (DreamerV3's and PlaNet's action repeat);
    # the model sees every action_repeat-th observation
    action_repeat: int = at_least(1, default=1)
    train_steps: int = at_least(1, default=100)  # gradient steps per update (unless replay_ratio is set)
    # DreamerV3's train ratio: replayed steps (batch_size x sequence_length per gradient step) per decision
    # collected; when set it fixes the gradient steps per update (see ``gradient_steps``), else train_steps does
    replay_ratio: float | None = positive(None)
    batch_size: int = at_least(1, default=16)  # sequences per gradient step
    # L, transitions of each sampled sequence (consecutive steps of one episode; the model reads L + 1 steps)
    sequence_length: int = at_least(2, default=50)
    # replay capacity in transitions, rounded down to a multiple of num_arenas (with a warning)
    buffer_size: int = at_least(1, default=1_000_000)
    learning_starts: int = at_least(0, default=5_000)  # environment steps of uniform actions first
    # environment steps of a run: total_steps // (num_arenas * rollout_length) updates (at least 1)
    total_steps: int = at_least(1, default=1_000_000)
    exploration_noise: float = non_negative(0.3)  # fraction of the action half-range (planet)

    @property
    def decisions_per_update(self) -> int:
        """Decisions of all the arenas per update: ``num_arenas * rollout_length``."""
        return self.num_arenas * self.rollout_length

    @property
    def steps_per_update(self) -> int:
        """Environment steps per update: the decisions times ``action_repeat``."""
        return self.decisions_per_update * self.action_repeat

    @property
    def gradient_steps(self) -> int:
        """Gradient steps per update: ``train_steps``, or with ``replay_ratio`` set,
        ``round(replay_ratio * decisions_per_update / (batch_size * sequence_length))``."""
        if self.replay_ratio is None:
            return self.train_steps
        return round(self.replay_ratio * self.decisions_per_update / (self.batch_size * self.sequence_length))

    def model_config(self) -> WorldModelConfig:
        return WorldModelConfig(**{f.name: getattr(self, f.name) for f in dataclasses.fields(WorldModelConfig)})


def check_online_config(cfg: OnlineConfig, agent: str) -> OnlineConfig:
    """``cfg`` checked, its ``buffer_size`` rounded down to a multiple of ``num_arenas`` (with a warning): each
    arena keeps ``buffer_size // num_arenas`` steps. Raises ``ValueError`` naming what to change."""
    cfg = rounded_buffer(cfg, agent)
    wm.compute_dtype(cfg, agent)
    if cfg.replay_ratio is not None and cfg.gradient_steps < 1:
        low = cfg.batch_size * cfg.sequence_length / (2 * cfg.decisions_per_update)
        raise ValueError(f"{agent}: replay_ratio={cfg.replay_ratio} gives less than one gradient step per update "
                         f"({cfg.decisions_per_update} decisions, batches of {cfg.batch_size} x {cfg.sequence_length} "
                         f"steps); use replay_ratio >= {low:g}, or more arenas or a longer rollout_length per update")
    if cfg.buffer_size // cfg.num_arenas < cfg.sequence_length:
        raise ValueError(f"{agent}: each arena keeps buffer_size / num_arenas = {cfg.buffer_size // cfg.num_arenas} "
                         f"steps, fewer than sequence_length={cfg.sequence_length}")
    return cfg


def decision_arena(arena: Arena, action_repeat: int) -> Arena:
    """``arena`` stepped a decision at a time: each action held for ``action_repeat`` of its steps through a
    ``repeat`` action tool in front of its own tools (``arena`` itself for 1). Warns when ``arena`` already repeats
    actions (``action:repeat(n)``): each decision then lasts n x ``action_repeat`` control steps."""
    if action_repeat == 1:
        return arena
    if arena.tool.substeps > 1:
        warnings.warn(f"arena {arena.build_string or arena.name!r} already repeats each action ({arena.tool.name}, "
                      f"{arena.tool.substeps} steps) and the config's action_repeat={action_repeat} holds it for "
                      f"{action_repeat} of those: each decision lasts {arena.tool.substeps * action_repeat} control "
                      f"steps; drop one of them for the published protocol", stacklevel=3)
    return dataclasses.replace(arena, tool=ActionTool.chain(tools.repeat(action_repeat), arena.tool))


def held_action(spec: Any, previous_action: jax.Array) -> jax.Array:
    """The arena's action (B, ...) that the model's vector ``previous_action`` (B, A) stands for."""
    if isinstance(spec, Discrete):
        return jnp.argmax(previous_action, -1).astype(spec.dtype)
    return previous_action.reshape(previous_action.shape[:1] + tuple(spec.shape)).astype(spec.dtype)


def hold_between_decisions(action_repeat: int, spec: Any, info: Info, memory: PyTree,
                           decide: Callable[[PyTree, Info], tuple[jax.Array, PyTree]]) -> tuple[jax.Array, PyTree]:
    """``decide(memory, info) -> (action, memory)`` at the arenas whose ``info.step`` is a multiple of
    ``action_repeat``; the others repeat the action in ``memory.previous_action`` and keep their memory.
    ``decide`` runs only in steps where some arena decides."""
    if action_repeat == 1:
        return decide(memory, info)
    deciding = info.step % action_repeat == 0

    def held(memory):
        return held_action(spec, memory.previous_action), memory

    action, decided = jax.lax.cond(jnp.any(deciding), lambda memory: decide(memory, info), held, memory)
    return jnp.where(deciding.reshape((-1,) + (1,) * (action.ndim - 1)), action,
                     held_action(spec, memory.previous_action)), restart(deciding, decided, memory)


def observation_inputs(model: wm.WorldModel, info: Info):
    """``(vector (B, D), images {key: (B, H, W, C)})`` laid out as :func:`wm.sequences_from_windows` does."""
    split = networks.split_observation(info, model.images)
    return split["vector"], split["images"]


def restart(first: jax.Array, fresh: PyTree, current: PyTree) -> PyTree:
    """``fresh`` where ``first`` (B,) is set, else ``current``, leafwise."""
    return jax.tree_util.tree_map(
        lambda new, old: jnp.where(first.reshape((-1,) + (1,) * (old.ndim - 1)), new, old), fresh, current)


def filter_belief(model: wm.WorldModel, params: dict, latent: Latent, previous_action: jax.Array,
                  info: Info) -> Latent:
    """The belief (B,) after ``info``'s observations: restarted at new episodes, then the posterior's mode."""
    first = info.step == 0
    latent = restart(first, model.initial(first.shape), latent)
    previous_action = jnp.where(first[:, None], 0.0, previous_action)
    vector, images = observation_inputs(model, info)
    embed = model.encoder.apply(params["encoder"], vector, images)
    latent, _, _ = model.rssm.apply(params["rssm"], latent, previous_action, embed, None, method=RSSMCell.obs_step)
    return latent


@struct.dataclass
class Collection:
    """The running collection: arenas, their infos and running returns, the buffer, the agent's memory."""

    arena_state: Any
    info: Info
    episode_return: jax.Array  # (B,)
    buffer: Any
    memory: Any


def collect(arena: Arena, cfg: OnlineConfig, buffer, running: Collection, env_steps: jax.Array,
            choose: Callable, key: jax.Array) -> tuple[Collection, dict]:
    """``cfg.rollout_length`` steps of the arenas (``arena``: the :func:`decision_arena`, a step per decision):
    ``choose(memory, info, key) -> (action, memory)`` acts, uniform actions replace it before ``learning_starts``
    environment steps; returns the collection and the per-step episode records."""
    spec = arena.spec
    params = arena.default_params()

    def step(running: Collection, xs):
        index, key = xs
        choose_key, random_key = jax.random.split(key)
        chosen, memory = choose(running.memory, running.info, choose_key)
        seeding = env_steps + index * cfg.num_arenas * cfg.action_repeat < cfg.learning_starts
        uniform = jax.vmap(spec.action.sample)(jax.random.split(random_key, cfg.num_arenas))
        action = jnp.where(seeding, uniform, chosen)
        memory = memory.replace(previous_action=wm.action_vector(spec.action, action, 1))
        arena_state, after = batch_step(arena, running.arena_state, action, params)
        buffer_state = buffer.add(running.buffer, transition_from(running.info, action, after))
        episode_return = running.episode_return + after.reward
        record = dict(done=after.done, finished_return=jnp.where(after.done, episode_return, 0.0),
                      faulted=after.faulted)
        return Collection(arena_state, after, jnp.where(after.done, 0.0, episode_return), buffer_state,
                          memory), record

    steps = (jnp.arange(cfg.rollout_length, dtype=jnp.int32), jax.random.split(key, cfg.rollout_length))
    return jax.lax.scan(step, running, steps)


def episode_metrics(record: dict, running_return: jax.Array) -> dict:
    """``episodes``, ``episode_return`` (mean over the episodes that ended), ``faulted_episodes`` and
    ``running_return``: the mean over the arenas of ``running_return`` (B,), what their unfinished episodes
    have earned so far, which shows progress before long episodes end."""
    finished = jnp.sum(record["done"])
    return dict(episodes=finished, episode_return=jnp.sum(record["finished_return"]) / jnp.maximum(finished, 1),
                faulted_episodes=jnp.sum(record["faulted"]), running_return=jnp.mean(running_return))


def model_step(model: wm.WorldModel, optimizer, buffer, buffer_state, params: dict, opt_state, key: jax.Array):
    """One world-model gradient step on a window batch: ``(params, opt_state, metrics, posterior latents (S, L+1))``."""
    sample_key, loss_key = jax.random.split(key)
    seq = wm.sequences_from_windows(model.spec, buffer.sample(buffer_state, sample_key).experience)
    return sequence_step(model, optimizer, params, opt_state, seq, loss_key)


def sequence_step(model: wm.WorldModel, optimizer, params: dict, opt_state, seq: wm.Sequences, key: jax.Array):
    """One world-model gradient step on ``seq`` (S, L+1), from the buffer or from a dataset (offline ``planet``):
    ``(params, opt_state, metrics, posterior latents (S, L+1))``."""
    # data parallel over the devices of a mesh (jarena.distributed): each device takes its share of the sequences,
    # the model stays whole on each, and XLA all-reduces the gradients
    params, opt_state = distributed.replicate((params, opt_state))
    seq = distributed.split_batch(seq)
    params, opt_state, metrics, latents = wm.gradient_step(model, optimizer, params, opt_state, seq, key)
    params, opt_state = distributed.replicate((params, opt_state))
    return params, opt_state, {k: metrics[k] for k in MODEL_METRICS}, latents


def learn_when_ready(ready: jax.Array, gradient_step: Callable, carry: PyTree, key: jax.Array, steps: int,
                     metric_names: tuple[str, ...]) -> tuple[PyTree, dict]:
    """``steps`` of ``gradient_step(carry, key) -> (carry, metrics)`` in a ``lax.scan`` where ``ready`` (a bool
    scalar: enough data), else ``carry`` unchanged; returns the carry and the metrics averaged (zeros if not)."""
    def learn(carry):
        carry, metrics = jax.lax.scan(gradient_step, carry, jax.random.split(key, steps))
        return carry, {k: jnp.mean(v) for k, v in metrics.items()}

    def wait(carry):
        return carry, {k: jnp.zeros((), jnp.float32) for k in metric_names}

    return jax.lax.cond(ready, learn, wait, carry)
