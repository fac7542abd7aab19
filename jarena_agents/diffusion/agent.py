"""Diffusion Policy (Chi et al., RSS 2023), CNN backbone, as a trainable jarena agent.

The policy generates a sequence of ``horizon`` (H = 16) actions by denoising Gaussian noise with a 1-D temporal
U-Net (:class:`jarena_agents.diffusion.networks.TemporalUnet`), conditioned by FiLM on the features of the last
``obs_horizon`` (T_o = 2) observations. Acting executes ``action_steps`` (T_a = 8) of them, the generated steps
``T_o - 1 .. T_o + T_a - 2`` (the first is aligned with the current observation), then generates anew (receding
horizon). The action chunk, the position in it and the observation history are per-arena agent state: the acting
state gets them from ``batch_state`` (or its first ``act``), ``reset`` restarts masked arenas and a new episode
(``info.step == 0``) restarts its arena under any runner.

Training reads a :class:`~jarena.data.dataset.TrajectoryDataset` (config key ``dataset``) whole onto the device,
as ``bc`` does, and draws padded windows of H steps (:mod:`jarena_agents.diffusion.data`). Actions and
low-dimensional observations (with the goal) are normalised to [-1, 1] from the dataset's limits. Each update is
one AdamW step (cosine learning rate after a linear warm-up) on DDPM's noise-prediction loss: a noise step
``t ~ U{0 .. diffusion_steps - 1}`` per window (the ``squaredcos_cap_v2`` schedule,
:mod:`jarena_agents.diffusion.schedule`), the squared error of the predicted noise. An exponential moving average
of the weights (Diffusion Policy's warm-up, power 0.75, at most 0.9999) is what acts. Acting samples with
``inference_steps`` deterministic DDIM steps (10 of the 100; ``sampler: ddpm`` takes ancestral DDPM steps instead,
as the paper's simulation results do with all 100), clipping the clean estimate to [-1, 1]; the noise of arena
``i`` is drawn from ``fold_in(key, i)``, so an arena's actions depend on its own observations and the key, whatever
the batch size. Train and eval modes act alike (the policy is a sampler either way).

Image observations (uint8 (H, W, C)) go through one ResNet-18-like encoder per image key (GroupNorm, spatial-softmax
keypoints: :class:`jarena_agents.diffusion.networks.ObservationEncoder`) after a ``crop`` x ``crop`` crop, random
per frame in training and central when acting; their features join the low-dimensional vector. State observations
condition the U-Net directly. A "step" of ``total_steps`` is one gradient update, as for ``bc``.

Defaults are the paper's where it states them: T_o 2, H 16, T_a 8; 100 DDPM steps; ``down_dims`` (256, 512,
1024), kernel 5, 8 groups, a 128-wide step embedding (its real-robot configuration, 65M parameters for the U-Net
with a PushT-like condition; the simulation benchmarks use ``down_dims: [512, 1024, 2048]``, 252M, and 100 DDPM
sampling steps); 84 x 84 crops; ResNet-18 widths, 32 keypoints, 64 features per image; batch 64, AdamW at 1e-4
with weight decay 1e-6 and betas (0.95, 0.999), 500 warm-up steps; EMA power 0.75.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from jarena import distributed
from jarena.core.agent import Agent
from jarena.core.arena import Arena, ArenaSpec
from jarena.core.spec import Box
from jarena.core.types import Info
from jarena_agents import networks as shared_networks
from jarena_agents.config import (
    ConfigError,
    DatasetSchedule,
    at_least,
    in_unit_interval,
    make_config,
    non_negative,
    positive,
)
from jarena_agents.datasets import to_device
from jarena_agents.diffusion import data, networks, schedule
from jarena_agents.diffusion.networks import ObservationEncoder, TemporalUnet, center_offsets, crop, random_offsets
from jarena_agents.registry import register_agent
from jarena_agents.trainable import TrainableAgent

PyTree = Any


@dataclasses.dataclass(frozen=True)
class DiffusionConfig(DatasetSchedule):
    """Diffusion Policy hyperparameters.

    Attributes:
      dataset: path of the TrajectoryDataset of demonstrations (needed for training, not for acting).
      obs_horizon: T_o, the observations (the current one and those before it) that condition a plan.
      horizon: H, the actions generated at once; a multiple of ``2^(len(down_dims) - 1)``.
      action_steps: T_a, the generated actions executed before planning again (``obs_horizon - 1 + action_steps
        <= horizon``).
      down_dims: the U-Net's channels at each level of its contracting path.
      kernel: the U-Net's convolution width along time (odd).
      groups: GroupNorm groups in the U-Net (each of ``down_dims`` a multiple).
      step_embedding: width of the diffusion step's sinusoidal embedding (even).
      diffusion_steps: noise steps of the DDPM training process.
      inference_steps: denoising steps when acting (at most ``diffusion_steps``).
      sampler: ``"ddim"`` (deterministic DDIM steps) or ``"ddpm"`` (ancestral DDPM steps with the posterior's
        fixed small variance, Diffusion Policy's sampler in its simulation benchmarks, with 100 steps).
      clip_sample: clip the denoised estimate to [-1, 1] (the normalised data's range) at every step.
      crop: side of the square image crops (random in training, central when acting); null keeps whole images.
      encoder_widths: channels of the image encoder's stages (ResNet-18: 64, 128, 256, 512).
      encoder_blocks: basic blocks per stage (ResNet-18: 2 each).
      encoder_group_size: channels per GroupNorm group in the image encoder.
      keypoints: spatial-softmax keypoints per image.
      image_features: features per image key.
      batch_size: windows per gradient step.
      learning_rate: AdamW's peak step size (linear warm-up, then a cosine decay to 0 at ``total_steps``).
      weight_decay: AdamW's decoupled weight decay.
      adam_b1: AdamW's first-moment decay.
      adam_b2: AdamW's second-moment decay.
      warmup_steps: updates of linear learning-rate warm-up (fewer than ``total_steps``).
      total_steps: gradient updates of a run.
      use_ema: act with the exponential moving average of the weights (else with the weights).
      ema_power: the average's warm-up power (decay ``1 - (1 + n)^-power`` at update n).
      ema_max_decay: the average's largest decay.
    """

    dataset: str = ""
    obs_horizon: int = at_least(1, default=2)
    horizon: int = at_least(1, default=16)
    action_steps: int = at_least(1, default=8)
    down_dims: tuple = (256, 512, 1024)
    kernel: int = at_least(1, default=5)
    groups: int = at_least(1, default=8)
    step_embedding: int = at_least(4, default=128)
    diffusion_steps: int = at_least(1, default=100)
    inference_steps: int = at_least(1, default=10)
    sampler: str = "ddim"
    clip_sample: bool = True
    crop: int | None = at_least(1, default=84)
    encoder_widths: tuple = (64, 128, 256, 512)
    encoder_blocks: tuple = (2, 2, 2, 2)
    encoder_group_size: int = at_least(1, default=16)
    keypoints: int = at_least(1, default=32)
    image_features: int = at_least(1, default=64)
    batch_size: int = at_least(1, default=64)
    learning_rate: float = positive(1e-4)
    weight_decay: float = non_negative(1e-6)
    adam_b1: float = in_unit_interval(0.95, open_high=True)
    adam_b2: float = in_unit_interval(0.999, open_high=True)
    warmup_steps: int = at_least(0, default=500)
    total_steps: int = at_least(1, default=100_000)
    use_ema: bool = True
    ema_power: float = positive(0.75)
    ema_max_decay: float = in_unit_interval(0.9999)


SAMPLERS = ("ddim", "ddpm")


def check_config(cfg: DiffusionConfig) -> None:
    """Raises a ``ConfigError`` naming the first inconsistency between fields (each field's own range is checked
    by :func:`jarena_agents.config.make_config`)."""
    problems = []
    dims = tuple(cfg.down_dims)
    if not dims or any(not isinstance(d, int) or d < 1 for d in dims):
        problems.append(f"down_dims must be a non-empty list of positive integers, got {list(dims)}")
    elif any(d % cfg.groups for d in dims):
        problems.append(f"each of down_dims {list(dims)} must be a multiple of groups ({cfg.groups})")
    elif cfg.horizon % 2 ** (len(dims) - 1):
        problems.append(f"horizon ({cfg.horizon}) must be a multiple of {2 ** (len(dims) - 1)}: the U-Net halves it "
                        f"{len(dims) - 1} times (len(down_dims) - 1)")
    if cfg.obs_horizon - 1 + cfg.action_steps > cfg.horizon:
        problems.append(f"obs_horizon - 1 + action_steps ({cfg.obs_horizon} - 1 + {cfg.action_steps}) must be at most "
                        f"horizon ({cfg.horizon}): the executed actions are generated steps obs_horizon - 1 onwards")
    if cfg.kernel % 2 == 0:
        problems.append(f"kernel must be odd (it keeps the sequence length), got {cfg.kernel}")
    if cfg.step_embedding % 2:
        problems.append(f"step_embedding must be even (sines and cosines), got {cfg.step_embedding}")
    if cfg.sampler not in SAMPLERS:
        problems.append(f"sampler must be one of {list(SAMPLERS)}, got {cfg.sampler!r}")
    if cfg.inference_steps > cfg.diffusion_steps:
        problems.append(f"inference_steps ({cfg.inference_steps}) must be at most diffusion_steps "
                        f"({cfg.diffusion_steps})")
    if cfg.warmup_steps >= cfg.total_steps:
        problems.append(f"warmup_steps ({cfg.warmup_steps}) must be fewer than total_steps ({cfg.total_steps})")
    widths, blocks = tuple(cfg.encoder_widths), tuple(cfg.encoder_blocks)
    if not widths or len(widths) != len(blocks) or any(not isinstance(x, int) or x < 1 for x in widths + blocks):
        problems.append(f"encoder_widths {list(widths)} and encoder_blocks {list(blocks)} must be lists of positive "
                        f"integers of one length (a stage each)")
    if problems:
        raise ConfigError("diffusion: " + "; ".join(problems))


def check_spec(cfg: DiffusionConfig, spec: ArenaSpec) -> None:
    """Raises a ``ConfigError`` unless the arena has bounded float Box actions and images the crop fits."""
    action = spec.action
    if not (isinstance(action, Box) and action.bounded and np.dtype(action.dtype).kind == "f"):
        raise ConfigError(f"diffusion generates continuous actions: it needs a bounded float Box action spec, got "
                          f"{action!r}")
    for key in shared_networks.image_keys(spec):
        height, width = spec.observation[key].shape[:2]
        if cfg.crop is not None and cfg.crop > min(height, width):
            raise ConfigError(f"diffusion: crop={cfg.crop} does not fit image {key!r} of {height} x {width}; set crop "
                              f"to at most {min(height, width)}, or null for whole images")


# ---------------------------------------------------------------------------------------------- states
@struct.dataclass
class Memory:
    """Per-arena acting memory.

    ``history``: the last T_o observations as the networks read them (``{"vector": float32 (B, T_o, D), "images":
    {key: uint8 (B, T_o, H, W, C)}}``, oldest first); ``chunk``: float32 (B, T_a, A), the actions being executed
    (flat, in the arena's units); ``position``: int32 (B,), the next of them (T_a: plan anew); ``started``: bool
    (B,), false until the arena's first observation (and again after ``reset``).
    """

    history: dict
    chunk: jax.Array
    position: jax.Array
    started: jax.Array


@struct.dataclass
class DiffusionState:
    """Acting state: the networks' parameters (``{"encoder", "unet"}``), the normaliser and, once fitted to a batch,
    the memory. ``deterministic`` (eval mode) changes nothing: the policy samples in both modes."""

    params: PyTree
    normalizer: data.Normalizer
    memory: Memory | None
    spec: ArenaSpec = struct.field(pytree_node=False)
    deterministic: bool = struct.field(pytree_node=False, default=True)


@struct.dataclass
class DiffusionTrainState:
    """Everything a run needs to continue bit for bit; ``data`` and ``lengths`` as
    :func:`jarena_agents.diffusion.data.read_dataset` gives them."""

    params: PyTree
    ema_params: PyTree
    opt_state: PyTree
    normalizer: data.Normalizer
    data: PyTree
    lengths: jax.Array
    key: jax.Array
    update: jax.Array  # int32, updates done


# ---------------------------------------------------------------------------------------------- the agent
def make_diffusion(config=None) -> TrainableAgent:
    cfg = make_config(DiffusionConfig, config, agent="diffusion")
    check_config(cfg)
    alphas_cumprod = schedule.cosine_alphas_cumprod(cfg.diffusion_steps)
    timesteps = schedule.ddim_timesteps(cfg.diffusion_steps, cfg.inference_steps)
    previous = timesteps - cfg.diffusion_steps // cfg.inference_steps
    unet_args = dict(down_dims=tuple(cfg.down_dims), kernel=cfg.kernel, groups=cfg.groups,
                     step_embedding=cfg.step_embedding)
    encoder = ObservationEncoder(tuple(cfg.encoder_widths), tuple(cfg.encoder_blocks), cfg.encoder_group_size,
                                 cfg.keypoints, cfg.image_features)
    first_executed = cfg.obs_horizon - 1

    def action_size(spec: ArenaSpec) -> int:
        return int(np.prod(spec.action.shape, dtype=int))

    def unet(spec: ArenaSpec) -> TemporalUnet:
        return TemporalUnet(action_size(spec), **unet_args)

    def bounds(spec: ArenaSpec) -> tuple[jax.Array, jax.Array]:
        """The action spec's bounds as flat float32 (A,) vectors."""
        return tuple(jnp.broadcast_to(jnp.asarray(b, jnp.float32), spec.action.shape).reshape(-1)
                     for b in (spec.action.low, spec.action.high))

    def cropped(images: dict, key=None) -> dict:
        """Frames (N, H, W, C) by key, cut to ``crop`` x ``crop``: at random per frame with ``key``, else centrally."""
        if cfg.crop is None:
            return images
        out = {}
        for i, k in enumerate(sorted(images)):
            count, height, width = images[k].shape[:3]
            offsets = (center_offsets(count, height, width, cfg.crop) if key is None
                       else random_offsets(jax.random.fold_in(key, i), count, height, width, cfg.crop))
            out[k] = crop(images[k], offsets, cfg.crop)
        return out

    def condition(params, normalizer: data.Normalizer, history: dict, key=None) -> jax.Array:
        """The U-Net's condition (S, T_o F) from observations ``{"vector": (S, T_o, D), "images": {k: (S, T_o, H, W,
        C)}}``: the normalised vector and, with images, their features (crops random per frame with ``key``)."""
        vector = data.to_unit(normalizer.vector, history["vector"])
        samples, steps, size = vector.shape
        if not history["images"]:
            return vector.reshape(samples, steps * size)
        frames = {k: v.reshape((samples * steps,) + v.shape[2:]) for k, v in history["images"].items()}
        features = encoder.apply(params["encoder"], {"vector": vector.reshape(samples * steps, size),
                                                     "images": cropped(frames, key)})
        return features.reshape(samples, steps * features.shape[-1])

    def init_params(key, spec: ArenaSpec) -> dict:
        check_spec(cfg, spec)
        encoder_key, unet_key = jax.random.split(key)
        history = fresh_memory(spec, 1).history
        encoder_params = {}
        if history["images"]:
            frames = cropped({k: v[:, 0] for k, v in history["images"].items()})
            encoder_params = networks.init_params(encoder, encoder_key, {"vector": history["vector"][:, 0],
                                                                         "images": frames})
        cond = jax.eval_shape(lambda: condition({"encoder": encoder_params}, identity_normalizer(spec), history))
        unet_params = networks.init_params(unet(spec), unet_key, jnp.zeros((1, cfg.horizon, action_size(spec))),
                                           jnp.zeros((1,), jnp.int32), jnp.zeros(cond.shape, jnp.float32))
        return {"encoder": encoder_params, "unet": unet_params}

    def identity_normalizer(spec: ArenaSpec) -> data.Normalizer:
        """Low-dimensional observations as they are, actions from their spec's bounds."""
        size = shared_networks.vector_size(spec, shared_networks.image_keys(spec))
        return data.Normalizer(action=data.Limits(*bounds(spec)),
                               vector=data.Limits(-jnp.ones((size,), jnp.float32), jnp.ones((size,), jnp.float32)))

    def fresh_memory(spec: ArenaSpec, num_arenas: int) -> Memory:
        images = shared_networks.image_keys(spec)
        size = shared_networks.vector_size(spec, images)
        history = {"vector": jnp.zeros((num_arenas, cfg.obs_horizon, size), jnp.float32),
                   "images": {k: jnp.zeros((num_arenas, cfg.obs_horizon) + spec.observation[k].shape,
                                           spec.observation[k].dtype) for k in images}}
        return Memory(history=history, chunk=jnp.zeros((num_arenas, cfg.action_steps, action_size(spec)), jnp.float32),
                      position=jnp.full((num_arenas,), cfg.action_steps, jnp.int32),
                      started=jnp.zeros((num_arenas,), bool))

    def init(key, spec: ArenaSpec, num_arenas: int) -> DiffusionState:
        return DiffusionState(params=init_params(key, spec), normalizer=identity_normalizer(spec),
                              memory=fresh_memory(spec, num_arenas), spec=spec)

    def batch_state(state: DiffusionState, num_arenas: int) -> DiffusionState:
        if state.memory is not None and state.memory.position.shape[0] == num_arenas:
            return state
        return state.replace(memory=fresh_memory(state.spec, num_arenas))

    def reset(state: DiffusionState, mask) -> DiffusionState:
        if state.memory is None:
            return state
        return state.replace(memory=state.memory.replace(started=state.memory.started & ~mask))

    def plan(spec: ArenaSpec, params, normalizer: data.Normalizer, history: dict, key) -> jax.Array:
        """Generated actions (B, T_a, A) in the arena's units (flat) for observation histories (B, T_o, ...); arena
        i's initial noise from ``fold_in(key, i)``."""
        count = history["vector"].shape[0]
        cond = condition(params, normalizer, history)
        shape = (cfg.horizon, action_size(spec))
        keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(jnp.arange(count))
        if cfg.sampler == "ddpm":  # each arena: its initial noise, and its steps' noise from a key of their own
            keys, step_keys = jnp.moveaxis(jax.vmap(jax.random.split)(keys), 1, 0)
        noise = jax.vmap(lambda k: jax.random.normal(k, shape))(keys)
        network = unet(spec)

        def denoise(x, steps):
            t, t_prev, index = steps
            epsilon = network.apply(params["unet"], x, jnp.full((count,), t), cond)
            if cfg.sampler == "ddim":
                return schedule.ddim_step(alphas_cumprod, x, epsilon, t, t_prev, cfg.clip_sample), None
            drawn = jax.vmap(lambda k: jax.random.normal(jax.random.fold_in(k, index), shape))(step_keys)
            return schedule.ddpm_step(alphas_cumprod, x, epsilon, t, t_prev, drawn, cfg.clip_sample), None

        steps = (jnp.asarray(timesteps), jnp.asarray(previous), jnp.arange(len(timesteps)))
        sample, _ = jax.lax.scan(denoise, noise, steps)
        executed = sample[:, first_executed:first_executed + cfg.action_steps]
        return jnp.clip(data.from_unit(normalizer.action, executed), *bounds(spec))

    def observe(spec: ArenaSpec, info: Info) -> dict:
        return shared_networks.split_observation(info, shared_networks.image_keys(spec))

    def remember(history: dict, current: dict, first: jax.Array) -> dict:
        """The history with ``current`` (leaves (B, ...)) appended, oldest dropped; filled with it where ``first``."""
        def push(old, new):
            shifted = jnp.concatenate([old[:, 1:], new[:, None].astype(old.dtype)], axis=1)
            filled = jnp.broadcast_to(new[:, None].astype(old.dtype), old.shape)
            return jnp.where(first.reshape((-1,) + (1,) * (old.ndim - 1)), filled, shifted)

        return jax.tree_util.tree_map(push, history, current)

    def act(state: DiffusionState, info: Info, key, privileged=None):
        spec = state.spec
        count = info.step.shape[0]
        memory = batch_state(state, count).memory
        first = (info.step == 0) | ~memory.started
        history = remember(memory.history, observe(spec, info), first)
        need = first | (memory.position >= cfg.action_steps)

        def replan():
            chunk = plan(spec, state.params, state.normalizer, history, key)
            return jnp.where(need[:, None, None], chunk, memory.chunk)

        chunk = jax.lax.cond(jnp.any(need), replan, lambda: memory.chunk)
        position = jnp.where(need, 0, memory.position)
        action = jnp.take_along_axis(chunk, position[:, None, None], axis=1)[:, 0]
        memory = Memory(history=history, chunk=chunk, position=position + 1, started=jnp.ones_like(memory.started))
        return action.reshape((count,) + spec.action.shape).astype(spec.action.dtype), state.replace(memory=memory)

    def optimizer():
        learning_rate = optax.warmup_cosine_decay_schedule(0.0, cfg.learning_rate, cfg.warmup_steps, cfg.num_updates)
        return optax.adamw(learning_rate, b1=cfg.adam_b1, b2=cfg.adam_b2, eps=1e-8, weight_decay=cfg.weight_decay)

    def init_training(key, arena: Arena) -> DiffusionTrainState:
        spec = arena.spec
        check_spec(cfg, spec)
        host = data.read_dataset(cfg.dataset, arena, shared_networks.image_keys(spec), cfg.horizon, cfg.obs_horizon,
                                 cfg.action_steps)
        device = to_device(host)
        key, init_key = jax.random.split(key)
        params = init_params(init_key, spec)
        normalizer = data.Normalizer(action=device["action_limits"], vector=device["vector_limits"])
        return DiffusionTrainState(params=params, ema_params=jax.tree_util.tree_map(jnp.copy, params),
                                   opt_state=optimizer().init(params), normalizer=normalizer, data=device["data"],
                                   lengths=device["lengths"], key=key, update=jnp.zeros((), jnp.int32))

    def policy(train_state: DiffusionTrainState, spec: ArenaSpec, deterministic: bool = True) -> DiffusionState:
        """The acting state of a trained agent (the moving average of its weights with ``use_ema``); its memory is
        allocated for the runner's batch."""
        params = train_state.ema_params if cfg.use_ema else train_state.params
        return DiffusionState(params=params, normalizer=train_state.normalizer, memory=None, spec=spec,
                              deterministic=deterministic)

    def loss_fn(spec: ArenaSpec, params, normalizer, inputs: dict, actions, noise, t, crop_key) -> jax.Array:
        """DDPM's noise-prediction loss: the mean squared error of the predicted noise over every action value."""
        cond = condition(params, normalizer, inputs, crop_key)
        noisy = schedule.add_noise(alphas_cumprod, data.to_unit(normalizer.action, actions), noise, t)
        return jnp.mean(jnp.square(unet(spec).apply(params["unet"], noisy, t, cond) - noise))

    def one_update(spec: ArenaSpec, ts: DiffusionTrainState):
        key, sample_key, noise_key, step_key, crop_key = jax.random.split(ts.key, 5)
        observation, goal, actions = data.sample_windows(ts.data, ts.lengths, sample_key, cfg.batch_size, cfg.horizon,
                                                         cfg.obs_horizon, cfg.action_steps)
        inputs = data.flatten(observation, goal, shared_networks.image_keys(spec), (cfg.batch_size, cfg.obs_horizon))
        noise = jax.random.normal(noise_key, actions.shape)
        t = jax.random.randint(step_key, (cfg.batch_size,), 0, cfg.diffusion_steps)
        # trained on a mesh: each device computes the loss of its share of the minibatch
        inputs, actions, noise, t = distributed.split_batch((inputs, actions, noise, t))
        loss, grads = jax.value_and_grad(loss_fn, argnums=1)(spec, ts.params, ts.normalizer, inputs, actions, noise,
                                                             t, crop_key)
        updates, opt_state = optimizer().update(grads, ts.opt_state, ts.params)
        params = optax.apply_updates(ts.params, updates)
        decay = schedule.ema_decay(ts.update, cfg.ema_power, cfg.ema_max_decay)
        ts = ts.replace(params=params, ema_params=schedule.ema_update(ts.ema_params, params, decay),
                        opt_state=opt_state, key=key, update=ts.update + 1)
        # No environment episodes finish while training from demonstrations: train_and_evaluate logs nan returns.
        return ts, dict(loss=loss, episodes=jnp.zeros((), jnp.int32), episode_return=jnp.zeros((), jnp.float32))

    def train(train_state: DiffusionTrainState, arena: Arena, num_updates: int):
        """Runs ``num_updates`` gradient steps (static) in one ``lax.scan``; metrics have a leading update axis."""
        return jax.lax.scan(lambda ts, _: one_update(arena.spec, ts), train_state, None, length=num_updates)

    agent = Agent(name="diffusion", init=init, act=act, reset=reset, batch_state=batch_state,
                  config=dataclasses.asdict(cfg))
    trainable = TrainableAgent.wrap(agent, init_training=init_training, train=train, policy=policy, settings=cfg)
    return trainable


register_agent("diffusion", make_diffusion, tags=("trainable", "imitation"))
