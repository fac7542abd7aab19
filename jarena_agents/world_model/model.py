"""A DreamerV3 world model of an arena (Hafner et al. 2023, arXiv 2301.04104): pure functions over its params.

The model reads sequences (:class:`Sequences`, leaves (B, T, ...)): at step t the observation ``o_t``, the
action ``a_{t-1}`` that led to it, the reward ``r_t`` received on arriving, whether the episode goes on
(``cont_t``), and ``is_first_t`` (the state restarts from the initial latent). :func:`sequences_from_windows`
builds them from the buffer's window samples (``jarena.data``, ``mode="window"``): a window of L transitions
gives L + 1 steps, the first of which starts the latent (its reward and continue flag are not trained).

Loss per step, as DreamerV3's: the observation's negative log-likelihood (symlog squared error summed over
the vector, squared error summed over the pixels of each image in [-0.5, 0.5]), the reward's two-hot
cross-entropy, the continue flag's Bernoulli NLL, plus ``dyn_scale * max(free_nats, KL[sg(q) || p])`` and
``rep_scale * max(free_nats, KL[q || sg(p)])`` (KL balancing with free bits); averaged over steps.

:func:`latent_model` is the seam to the planners: a :class:`jarena_agents.planners.model.Model` whose state
is a :class:`Latent`, so CEM and MPPI plan over the learned model as they plan over an arena's dynamics.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from jarena.core.arena import ArenaSpec
from jarena.core.spec import Box, Discrete
from jarena.data.experience import Experience
from jarena_agents import networks
from jarena_agents.config import ConfigError, at_least, in_unit_interval, non_negative, positive
from jarena_agents.planners.model import Model, check_action_spec
from jarena_agents.world_model import distributions as dist
from jarena_agents.world_model.networks import Decoder, Encoder, Head, Latent, RSSMCell

PyTree = Any


@dataclasses.dataclass(frozen=True)
class WorldModelConfig:
    """World-model sizes and loss weights (defaults: DreamerV3's "S" model is deter 512, hidden 512, cnn
    depth 32; its 32 x 32 latents, 255 bins, free bits 1, scales 0.5 / 0.1, lr 1e-4, clip 1000)."""

    deter: int = at_least(1, default=512)  # D, the width of the GRU's deterministic state
    stoch: int = at_least(1, default=32)  # S, the categorical variables of the stochastic state
    classes: int = at_least(2, default=32)  # K, the classes of each of them (the features are D + S K wide)
    # width of the hidden layers of the RSSM (GRU input, prior, posterior), of the vector encoder and decoder, of
    # the reward and continue heads, and of dreamer's actor and critic
    hidden: int = at_least(1, default=512)
    layers: int = at_least(1, default=2)  # hidden layers of the vector encoder, decoder and heads
    cnn_depth: int = at_least(1, default=32)  # channels of the first image convolution, doubled at each next one
    cnn_layers: int = at_least(1, default=4)  # stride-2 convolutions: 64 x 64 -> 4 x 4
    # two-hot bins of the reward head (and of dreamer's critic), equally spaced in symlog space over [-20, 20]
    bins: int = at_least(2, default=255)
    # fraction of the uniform distribution mixed into the latents' categoricals (prior and posterior)
    unimix: float = in_unit_interval(0.01, open_high=True)
    # free bits: each step's KL (nats, summed over the S variables) counts as at least this, with no gradient below
    free_nats: float = non_negative(1.0)
    dyn_scale: float = non_negative(0.5)  # weight of KL[sg(posterior) || prior]: trains the prior
    rep_scale: float = non_negative(0.1)  # weight of KL[posterior || sg(prior)]: trains the posterior
    model_learning_rate: float = positive(1e-4)  # Adam's (eps 1e-8), for the world model's parameters
    model_grad_clip: float = positive(1000.0)  # global-norm clip of the world model's gradients
    # steps of each sequential scan (filtering, imagination, returns) unrolled into one loop iteration: fewer,
    # larger iterations, a speed knob where each iteration's launch costs more than its work (small batches on a
    # GPU); the same computation, up to floating-point rounding
    scan_unroll: int = at_least(1, default=1)
    # dtype of the networks' matrix products and activations: "float32", or "bfloat16" as DreamerV3 trains (its
    # precision 16): parameters, LayerNorm statistics, the latent state, distributions and losses stay float32.
    # A speed knob for GPUs with bfloat16 units (slower on most CPUs)
    compute_dtype: str = "float32"


COMPUTE_DTYPES = ("float32", "bfloat16")


def compute_dtype(config: WorldModelConfig, agent: str = "world model"):
    """``config.compute_dtype`` as a jnp dtype; a ConfigError naming the choices for any other value."""
    if config.compute_dtype not in COMPUTE_DTYPES:
        raise ConfigError(f"config key 'compute_dtype' of agent {agent!r} must be one of {list(COMPUTE_DTYPES)}, "
                          f"got {config.compute_dtype!r}")
    return jnp.dtype(config.compute_dtype)


@struct.dataclass
class Sequences:
    """Model inputs, leaves (B, T, ...): ``vector`` float32 (B, T, D); ``images`` {key: uint8 (B, T, H, W, C)};
    ``action`` float32 (B, T, A), the action that led to step t (zeros where ``is_first``); ``reward``
    float32; ``cont`` float32 (0 where the episode terminated); ``is_first`` bool; ``mask`` float32, 1 where
    the reward and continue flag are trained."""

    vector: jax.Array
    images: dict
    action: jax.Array
    reward: jax.Array
    cont: jax.Array
    is_first: jax.Array
    mask: jax.Array


def action_size(spec: Any) -> int:
    """Length of the model's action vector: the flattened Box, or a one-hot of a Discrete's ``n``."""
    if isinstance(spec, Discrete):
        return int(spec.n)
    if isinstance(spec, Box) and np.issubdtype(spec.dtype, np.floating):
        return int(np.prod(spec.shape, dtype=int))
    raise ValueError(f"the world model reads Box (float) or Discrete actions, got {spec!r}")


def action_vector(spec: Any, action: jax.Array, batch_dims: int) -> jax.Array:
    """``action`` (*batch, ...) as the model's float32 vector (*batch, A)."""
    if isinstance(spec, Discrete):
        return jax.nn.one_hot(action, int(spec.n), dtype=jnp.float32)
    return action.reshape(action.shape[:batch_dims] + (-1,)).astype(jnp.float32)


@dataclasses.dataclass(frozen=True, eq=False)
class WorldModel:
    """The modules of a world model of one arena's spec, and its config. Functions below take its params."""

    config: WorldModelConfig
    spec: ArenaSpec
    images: tuple[str, ...]
    vector_size: int
    action_size: int

    @property
    def rssm(self) -> RSSMCell:
        c = self.config
        return RSSMCell(c.deter, c.stoch, c.classes, c.hidden, c.unimix, compute_dtype(c))

    @property
    def encoder(self) -> Encoder:
        c = self.config
        return Encoder(c.hidden, c.layers, c.cnn_depth, c.cnn_layers, compute_dtype(c))

    @property
    def decoder(self) -> Decoder:
        c = self.config
        shapes = tuple((k, tuple(self.spec.observation[k].shape)) for k in self.images)
        return Decoder(self.vector_size, shapes, c.hidden, c.layers, c.cnn_depth, c.cnn_layers, compute_dtype(c))

    @property
    def reward_head(self) -> Head:
        c = self.config
        return Head(c.bins, c.hidden, c.layers, zero_init=True, dtype=compute_dtype(c))

    @property
    def continue_head(self) -> Head:
        c = self.config
        return Head(1, c.hidden, c.layers, dtype=compute_dtype(c))

    @property
    def centres(self) -> jax.Array:
        return dist.bins(self.config.bins)

    def initial(self, batch_shape: tuple[int, ...] = ()) -> Latent:
        """The latent every sequence starts from (zeros), (*batch_shape, ...)."""
        c = self.config
        return Latent(jnp.zeros(batch_shape + (c.deter,), jnp.float32),
                      jnp.zeros(batch_shape + (c.stoch, c.classes), jnp.float32))


def make_world_model(spec: ArenaSpec, config: WorldModelConfig | None = None) -> WorldModel:
    """The world model of arenas of ``spec`` (observations: a vector and any uint8 (H, W, C) images, whose
    sides must divide by ``2^cnn_layers``)."""
    config = config or WorldModelConfig()
    compute_dtype(config)
    images = networks.image_keys(spec)
    for key in images:
        height, width, _ = spec.observation[key].shape
        if height % 2 ** config.cnn_layers or width % 2 ** config.cnn_layers:
            raise ConfigError(f"world model: image {key!r} is {height} x {width}; with cnn_layers = "
                              f"{config.cnn_layers} its sides must divide by {2 ** config.cnn_layers} "
                              f"(e.g. pixels:64 with 4 layers)")
    return WorldModel(config, spec, images, networks.vector_size(spec, images), action_size(spec.action))


def init_params(model: WorldModel, key: jax.Array) -> dict:
    """Parameters of every module: ``{"encoder", "rssm", "decoder", "reward", "continue"}``."""
    keys = jax.random.split(key, 5)
    vector = jnp.zeros((1, model.vector_size), jnp.float32)
    images = {k: jnp.zeros((1,) + tuple(model.spec.observation[k].shape), jnp.uint8) for k in model.images}
    encoder = model.encoder.init(keys[0], vector, images)
    embed = model.encoder.apply(encoder, vector, images)
    latent = model.initial((1,))
    rssm = model.rssm.init(keys[1], latent, jnp.zeros((1, model.action_size)), embed, None)
    features = latent.features()
    return {"encoder": encoder, "rssm": rssm, "decoder": model.decoder.init(keys[2], features),
            "reward": model.reward_head.init(keys[3], features),
            "continue": model.continue_head.init(keys[4], features)}


def sequences_from_windows(spec: ArenaSpec, experience) -> Sequences:
    """Model inputs from window samples of L transitions (``jarena.data.Experience``, leaves (B, L, ...)):
    L + 1 steps, ``o_0`` then each transition's next observation, step 0 starting the latent."""
    images = networks.image_keys(spec)
    steps = lambda first, rest: jnp.concatenate([first[:, :1], rest], 1)  # (B, 1 + L, ...)
    observations = jax.tree_util.tree_map(steps, experience.observation, experience.next_observation)
    leaves = jax.tree_util.tree_leaves({k: v for k, v in observations.items() if k not in images})
    leaves.append(steps(experience.goal, experience.goal))
    vector = jnp.concatenate([x.reshape(x.shape[:2] + (-1,)).astype(jnp.float32) for x in leaves], -1)
    image_obs = {k: observations[k] for k in images}
    batch, length = experience.reward.shape
    pad = lambda x, value: jnp.concatenate([jnp.full((batch, 1) + x.shape[2:], value, x.dtype), x], 1)
    action = action_vector(spec.action, experience.action, 2)
    return Sequences(vector=vector, images=image_obs, action=pad(action, 0.0),
                     reward=pad(experience.reward.astype(jnp.float32), 0.0),
                     cont=pad(1.0 - experience.terminated.astype(jnp.float32), 1.0),
                     is_first=jnp.arange(length + 1)[None, :].repeat(batch, 0) == 0,
                     mask=pad(jnp.ones((batch, length), jnp.float32), 0.0))


def sequences_from_dataset(spec: ArenaSpec, batch: dict) -> Sequences:
    """Model inputs from a :class:`jarena.data.Loader` batch in ``mode="window"`` (leaves (S, L, ...), read
    from a ``TrajectoryDataset`` of the arena, e.g. one written by ``jarena collect``): as
    :func:`sequences_from_windows`, for training the model offline."""
    (action,) = jax.tree_util.tree_leaves(batch["action"])
    shape = batch["reward"].shape
    goals = [g.reshape(shape + (-1,)).astype(jnp.float32) for g in jax.tree_util.tree_leaves(batch["goal"])]
    goal = jnp.concatenate(goals, -1) if goals else jnp.zeros(shape + (0,), jnp.float32)
    zeros = jnp.zeros(shape, bool)
    experience = Experience(observation=dict(batch["observation"]), action=action, reward=batch["reward"],
                            terminated=batch["terminated"], truncated=batch["truncated"], success=zeros,
                            next_observation=dict(batch["next_observation"]), goal=goal,
                            episode=jnp.zeros(shape, jnp.int32), step=batch["step"])
    return sequences_from_windows(spec, experience)


def observe(model: WorldModel, params: dict, seq: Sequences, key: jax.Array | None,
            start: Latent | None = None):
    """Filters ``seq`` (B, T) through the RSSM: ``(posterior latents (B, T), posterior probs, prior probs)``,
    probs (B, T, S, K). ``key`` None takes modes instead of samples; ``start`` (B,) defaults to the initial
    latent (used where ``is_first``)."""
    embed = model.encoder.apply(params["encoder"], seq.vector, seq.images)
    batch = seq.reward.shape[0]
    start = model.initial((batch,)) if start is None else start
    keys = None if key is None else jax.random.split(key, seq.reward.shape[1])

    def step(latent, inputs):
        embed_t, action_t, first_t, key_t = inputs
        reset = lambda x, init: jnp.where(first_t.reshape((-1,) + (1,) * (x.ndim - 1)), init, x)
        latent = jax.tree_util.tree_map(reset, latent, model.initial((batch,)))
        action_t = jnp.where(first_t[:, None], 0.0, action_t)
        latent, posterior = model.rssm.apply(params["rssm"], latent, action_t, embed_t, key_t,
                                             method=RSSMCell.posterior_step)
        return latent, (latent, posterior)

    time_major = lambda x: jnp.swapaxes(x, 0, 1)
    xs = (time_major(embed), time_major(seq.action), time_major(seq.is_first), keys)
    _, (latents, posteriors) = jax.lax.scan(step, start, xs, unroll=model.config.scan_unroll)
    latents, posteriors = jax.tree_util.tree_map(time_major, (latents, posteriors))
    # the prior depends on each step's deter alone: one batched head after the loop, not a step of it
    return latents, posteriors, model.rssm.apply(params["rssm"], latents.deter, method=RSSMCell.prior)


def imagine(model: WorldModel, params: dict, start: Latent, actions: jax.Array, key: jax.Array | None) -> Latent:
    """Rolls the prior forward from ``start`` (B,) under ``actions`` (B, H, A): latents (B, H)."""
    keys = None if key is None else jax.random.split(key, actions.shape[1])

    def step(latent, inputs):
        action_t, key_t = inputs
        latent, _ = model.rssm.apply(params["rssm"], latent, action_t, key_t, method=RSSMCell.img_step)
        return latent, latent

    _, latents = jax.lax.scan(step, start, (jnp.swapaxes(actions, 0, 1), keys), unroll=model.config.scan_unroll)
    return jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1), latents)


def decode(model: WorldModel, params: dict, latent: Latent) -> tuple[jax.Array | None, dict]:
    """Predicted observations of ``latent`` (*): the vector in its own units (symexp of the decoder's
    output) and each image as float in [0, 255]."""
    vector, images = model.decoder.apply(params["decoder"], latent.features())
    vector = None if vector is None else dist.symexp(vector)
    return vector, {k: jnp.clip((v + 0.5) * 255.0, 0.0, 255.0) for k, v in images.items()}


def predict_reward(model: WorldModel, params: dict, latent: Latent) -> jax.Array:
    """Predicted reward on arriving at ``latent`` (*)."""
    return dist.two_hot_mean(model.reward_head.apply(params["reward"], latent.features()), model.centres)


def continue_probability(model: WorldModel, params: dict, latent: Latent) -> jax.Array:
    """Predicted probability that the episode goes on after ``latent`` (*)."""
    return jax.nn.sigmoid(model.continue_head.apply(params["continue"], latent.features())[..., 0])


def loss(model: WorldModel, params: dict, seq: Sequences, key: jax.Array):
    """``(scalar loss, (metrics dict of scalars, posterior latents (B, T)))``: DreamerV3's world-model loss."""
    c = model.config
    latents, posterior, prior = observe(model, params, seq, key)
    features = latents.features()
    vector, images = model.decoder.apply(params["decoder"], features)
    observation = jnp.zeros(seq.reward.shape)
    if vector is not None:
        observation += jnp.sum((vector - dist.symlog(seq.vector)) ** 2, -1)
    for k, predicted in images.items():
        target = seq.images[k].astype(jnp.float32) / 255.0 - 0.5
        observation += jnp.sum((predicted - target) ** 2, axis=(-3, -2, -1))
    reward = dist.two_hot_loss(model.reward_head.apply(params["reward"], features), seq.reward, model.centres)
    cont = dist.bernoulli_loss(model.continue_head.apply(params["continue"], features)[..., 0], seq.cont)
    sg = jax.lax.stop_gradient
    dyn = dist.categorical_kl(sg(posterior), prior)
    rep = dist.categorical_kl(posterior, sg(prior))
    mask = seq.mask
    masked_mean = lambda x: jnp.sum(x * mask) / jnp.maximum(jnp.sum(mask), 1.0)
    terms = {"observation": jnp.mean(observation), "reward": masked_mean(reward), "continue": masked_mean(cont),
             "dyn": jnp.mean(jnp.maximum(dyn, c.free_nats)), "rep": jnp.mean(jnp.maximum(rep, c.free_nats))}
    total = (terms["observation"] + terms["reward"] + terms["continue"]
             + c.dyn_scale * terms["dyn"] + c.rep_scale * terms["rep"])
    metrics = {**{f"{k}_loss": v for k, v in terms.items()}, "kl": jnp.mean(dyn),
               "prior_entropy": jnp.mean(dist.categorical_entropy(prior)), "model_loss": total}
    return total, (metrics, latents)


def clip_by_flat_global_norm(max_norm: float) -> optax.GradientTransformation:
    """``optax.clip_by_global_norm(max_norm)``, the norm taken over all leaves concatenated (one reduction).

    The same updates up to float rounding. Why not optax's: its per-leaf sums of squares, inside the scanned
    gradient steps of a world model with batches of 32 or more sequences, stop XLA's GPU compiler (jax 0.11.2,
    H200: "Expected instruction to have shape equal to f32[], actual shape is f32[1]" at the square of a size-1
    gradient leaf); this form compiles (``benchmarks/dreamer_compile_check.sh``).
    """
    def update(updates, state, params=None):
        del params
        leaves = jax.tree_util.tree_leaves(updates)
        flat = jnp.concatenate([jnp.ravel(leaf) for leaf in leaves]) if leaves else jnp.zeros((0,))
        norm = jnp.sqrt(jnp.sum(jnp.square(flat)))
        scale = jnp.where(norm < max_norm, 1.0, max_norm / jnp.maximum(norm, 1e-38))
        return jax.tree_util.tree_map(lambda t: (t * scale).astype(t.dtype), updates), state
    return optax.GradientTransformation(lambda params: optax.EmptyState(), update)


def model_optimizer(config: WorldModelConfig) -> optax.GradientTransformation:
    """Adam (eps 1e-8) after global-norm clipping at ``model_grad_clip``, as DreamerV3's model optimiser."""
    return optax.chain(clip_by_flat_global_norm(config.model_grad_clip),
                       optax.adam(config.model_learning_rate, eps=1e-8))


def gradient_step(model: WorldModel, optimizer: optax.GradientTransformation, params: dict, opt_state,
                  seq: Sequences, key: jax.Array):
    """One gradient step on :func:`loss`: ``(params, opt_state, metrics, posterior latents (B, T))``; the
    latents are where Dreamer starts imagining. Pure; the caller jits."""
    (_, (metrics, latents)), grads = jax.value_and_grad(loss, argnums=1, has_aux=True)(model, params, seq, key)
    updates, opt_state = optimizer.update(grads, opt_state, params)
    metrics["grad_norm"] = optax.global_norm(grads)
    return optax.apply_updates(params, updates), opt_state, metrics, latents


def train_step(model: WorldModel, optimizer: optax.GradientTransformation, params: dict, opt_state,
               seq: Sequences, key: jax.Array):
    """One gradient step on :func:`loss`: ``(params, opt_state, metrics)``. Pure; the caller jits."""
    return gradient_step(model, optimizer, params, opt_state, seq, key)[:3]


def latent_model(model: WorldModel, params: dict, name: str = "world model") -> Model:
    """The learned model as a planner's :class:`~jarena_agents.planners.model.Model`: state one
    :class:`Latent` (no batch axis), ``step`` the prior's mode under an action of the arena's Box, reward the
    reward head's prediction, ``done`` where the continue head gives less than one half."""
    spec = check_action_spec(model.spec.action, name)

    def step(latent: Latent, action):
        vector = action_vector(spec, action, 0)
        latent, _ = model.rssm.apply(params["rssm"], latent, vector, None, method=RSSMCell.img_step)
        return latent, predict_reward(model, params, latent), continue_probability(model, params, latent) < 0.5

    shape = jax.eval_shape(lambda: model.initial())
    no_op = np.zeros(spec.shape, np.float32).clip(spec.low, spec.high)
    return Model(step=step, action_spec=spec, no_op=no_op, state_shape=shape, name=name)
