"""Behaviour cloning (BC) as a trainable jarena agent: supervised learning of a policy from demonstrations.

Training reads a :class:`~jarena.data.dataset.TrajectoryDataset` (config key ``dataset``: its path, e.g.
collected with ``jarena collect oracle_pendulum ...``) whole into device memory, and each update is one
gradient step on a minibatch drawn on device inside the compiled chunk, so ``train_and_evaluate`` drives
it like any trainable agent. There are no environment episodes during training: a "step" is one
gradient update (``steps_per_update = 1``, ``total_steps`` updates), and the metrics report
``episodes = 0`` (``train_and_evaluate`` then logs the training return as nan; validation and the final
evaluation run the policy on the arena's val and eval episodes as usual).

Policies (config ``policy``):
  ``deterministic``: an MLP regressing the action (mean squared error in the action spec's bounds scaled
    to [-1, 1]) for Box actions, or classifying it (cross-entropy; eval takes the argmax, train mode
    samples) for Discrete actions.
  ``gaussian``: for Box actions, a diagonal Gaussian with state-dependent mean and log standard
    deviation trained by negative log-likelihood, weighted as beta-NLL (``nll_beta``: with the plain NLL,
    0, the mean stops learning wherever the std grows, and a cloned pendulum swing-up fails); eval acts
    with the mean, train mode samples.
  ``mixture``: for Box actions, a mixture of ``components`` diagonal Gaussians (a mixture density network,
    as robomimic's GMM policy) trained by negative log-likelihood; eval acts with the mean of the most
    probable component. For demonstrations with several distinct good actions (which cloth corner to
    pull), where the regression and the single Gaussian learn their useless average.

Action chunks (config ``chunk = K``): the network predicts the K actions that follow an observation in
the demonstration (K-step windows of one trajectory, drawn uniformly with
:func:`jarena.data.loader.draw_indices`) and ``act`` executes the first of them, predicting anew at
every step (receding horizon). It keeps no queue of the rest: ``policy(train_state, spec)`` is called
without the number of arenas (e.g. by ``train_and_evaluate``'s evaluation), so the acting state cannot
hold per-arena buffers.

Observations are flattened as :func:`jarena_agents.networks.flatten_observation` does (fields sorted by
name, then the goal) and, with ``normalize_observations``, standardised with the dataset's mean and
variance (over every stored observation). Image observations (uint8 (H, W, C),
:func:`jarena_agents.networks.image_keys`) instead go through a CNN (``cnn`` layers of
:class:`jarena_agents.networks.PixelEncoder`) whose features join the other, flattened fields before the MLP,
as PPO's pixel networks do. Images are not shifted (DrQ's augmentation), since a shifted image would need a
shifted action; with ``augment: rotate90`` each sample is turned by a random number of quarter turns, its
actions read as normalised image points ``(u, v)`` turned with it (:func:`jarena_agents.augment.random_rotate90`):
for top-down views of scenes with no preferred direction and pixel-point actions, such as the cloth arenas'
``pixel_pick_and_place``, it gives four times the demonstrations.

The dataset lives in the train state (as a replay buffer would: checkpoints carry it, and a resumed run
continues bit for bit even if the file changed since). ``init_training`` reads it on the host when it is
traced and hands it to the device through a host callback, so no compiled program embeds it as a
constant; a dataset must therefore fit in device memory (stream larger ones with
:class:`jarena.data.Loader` in a custom loop).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from jarena import distributed
from jarena.core.agent import Agent
from jarena.core.arena import Arena, ArenaSpec
from jarena.core.spec import Box, Discrete, Spec
from jarena.core.types import Info
from jarena.data.loader import draw_indices
from jarena.data.schema import DatasetError
from jarena_agents import augment, networks, normalizer
from jarena_agents.bc import losses
from jarena_agents.config import (
    ConfigError,
    DatasetSchedule,
    at_least,
    in_unit_interval,
    make_config,
    non_negative,
    positive,
)
from jarena_agents.datasets import read_steps, to_device
from jarena_agents.registry import register_agent
from jarena_agents.trainable import TrainableAgent

PyTree = Any
LOG_STD_RANGE = (-5.0, 2.0)  # the Gaussian head's log std (in [-1, 1] action units), squashed in by a tanh
MIN_VARIANCE = 1e-6  # floor of the observation variance used for normalisation (constant features)


@dataclasses.dataclass(frozen=True)
class BCConfig(DatasetSchedule):
    """BC hyperparameters.

    Attributes:
      dataset: path of the TrajectoryDataset of demonstrations (needed for training, not for acting).
      policy: ``"deterministic"``, ``"gaussian"`` or ``"mixture"`` (the last two: Box actions only); see the
        module docstring.
      chunk: K, the number of consecutive actions predicted from one observation (``act`` runs the first).
      hidden: widths of the MLP's tanh layers.
      batch_size: observations (each with its K actions) per gradient step.
      learning_rate: Adam's step size; with ``anneal_lr`` it decays to 0 along a cosine over ``total_steps``.
      anneal_lr: decay the learning rate to 0 along a cosine over the run's ``total_steps`` gradient updates;
        if false it stays constant.
      max_grad_norm: global gradient-norm clip (0 disables it).
      total_steps: gradient updates of a run.
      normalize_observations: standardise observations with the dataset's statistics.
      nll_beta: the ``gaussian`` policy's beta-NLL weight (:func:`jarena_agents.bc.losses.gaussian_nll`; 0 is
        the plain negative log-likelihood, 0.5 keeps the mean learning where the std grows).
      components: M, the ``mixture`` policy's Gaussians.
      augment: ``"none"`` or ``"rotate90"`` (see the module docstring; image observations only, and actions
        in [-1, 1] that are image points).
      cnn: ``(features, kernel, stride)`` of the image encoder's ReLU convolutions (arenas with image
        observations only; default: the Nature DQN's).
      cnn_padding: the convolutions' padding, ``"VALID"`` or ``"SAME"``.
      cnn_output: ``"flatten"`` (the last feature maps, flattened) or ``"spatial_softmax"`` (each map's
        expected image point: :class:`jarena_agents.networks.PixelEncoder`).
    """

    dataset: str = ""
    policy: str = "deterministic"
    chunk: int = at_least(1, default=1)
    hidden: tuple = (256, 256)
    batch_size: int = at_least(1, default=256)
    learning_rate: float = positive(1e-3)
    anneal_lr: bool = True
    max_grad_norm: float = non_negative(1.0)
    total_steps: int = at_least(1, default=10_000)
    normalize_observations: bool = True
    nll_beta: float = in_unit_interval(0.5)
    components: int = at_least(1, default=5)
    augment: str = "none"
    cnn: tuple = networks.PixelEncoder.layers
    cnn_padding: str = networks.PixelEncoder.padding
    cnn_output: str = networks.PixelEncoder.output


# ---------------------------------------------------------------------------------------------- policy heads
@dataclasses.dataclass(frozen=True)
class Head:
    """How the network's output (F values per predicted step) becomes a loss and an action.

    Attributes:
      features: ``(spec, config) -> F``.
      loss: ``(spec, config, outputs (..., K, F), actions (..., K, *spec.shape)) -> float32 scalar``.
      act: ``(spec, config, outputs (..., F), key, deterministic) -> action (..., *spec.shape)`` in the spec.
    """

    features: Callable[[Spec, Any], int]
    loss: Callable[[Spec, Any, jax.Array, jax.Array], jax.Array]
    act: Callable[[Spec, Any, jax.Array, jax.Array, bool], jax.Array]


def _size(spec: Box) -> int:
    return int(np.prod(spec.shape, dtype=int))


def to_unit(spec: Box, action: jax.Array) -> jax.Array:
    """Box actions (..., *shape) -> float32 (..., d) scaled from [low, high] to [-1, 1]."""
    low, high = jnp.asarray(spec.low, jnp.float32), jnp.asarray(spec.high, jnp.float32)
    unit = 2.0 * (action.astype(jnp.float32) - low) / (high - low) - 1.0
    return unit.reshape(action.shape[:action.ndim - len(spec.shape)] + (-1,))


def _split_gaussian(outputs: jax.Array) -> tuple[jax.Array, jax.Array]:
    mean, raw = jnp.split(outputs, 2, axis=-1)
    low, high = LOG_STD_RANGE
    return mean, low + 0.5 * (high - low) * (jnp.tanh(raw) + 1.0)  # a soft clip: gradients never vanish


def _gaussian_act(spec, cfg, outputs, key, deterministic):
    mean, log_std = _split_gaussian(outputs)
    raw = mean if deterministic else mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape)
    return networks.to_env_action(spec, raw)


def _split_mixture(outputs: jax.Array, components: int) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Outputs (..., M (1 + 2 d)) -> mixture logits (..., M), means and log stds (..., M, d)."""
    logits, rest = outputs[..., :components], outputs[..., components:]
    mean, log_std = _split_gaussian(rest.reshape(rest.shape[:-1] + (components, -1)))
    return logits, mean, log_std


def _mixture_loss(spec, cfg, outputs, actions):
    return losses.mixture_nll(*_split_mixture(outputs, cfg.components), to_unit(spec, actions))


def _mixture_act(spec, cfg, outputs, key, deterministic):
    """Eval: the mean of the most probable component; train mode samples a component, then its Gaussian."""
    logits, mean, log_std = _split_mixture(outputs, cfg.components)
    component_key, noise_key = jax.random.split(key)
    pick = jnp.argmax(logits, -1) if deterministic else jax.random.categorical(component_key, logits)
    mean = jnp.take_along_axis(mean, pick[..., None, None], axis=-2)[..., 0, :]
    log_std = jnp.take_along_axis(log_std, pick[..., None, None], axis=-2)[..., 0, :]
    raw = mean if deterministic else mean + jnp.exp(log_std) * jax.random.normal(noise_key, mean.shape)
    return networks.to_env_action(spec, raw)


def _categorical_act(spec, cfg, logits, key, deterministic):
    action = jnp.argmax(logits, -1) if deterministic else jax.random.categorical(key, logits)
    return action.astype(spec.dtype)


HEADS: dict[tuple[str, type], Head] = {
    ("deterministic", Box): Head(
        features=lambda spec, cfg: _size(spec),
        loss=lambda spec, cfg, out, actions: losses.mse(out, to_unit(spec, actions)),
        act=lambda spec, cfg, out, key, deterministic: networks.to_env_action(spec, out)),
    ("gaussian", Box): Head(
        features=lambda spec, cfg: 2 * _size(spec),
        loss=lambda spec, cfg, out, actions: losses.gaussian_nll(*_split_gaussian(out), to_unit(spec, actions),
                                                                cfg.nll_beta),
        act=_gaussian_act),
    ("mixture", Box): Head(
        features=lambda spec, cfg: cfg.components * (1 + 2 * _size(spec)),
        loss=_mixture_loss,
        act=_mixture_act),
    ("deterministic", Discrete): Head(
        features=lambda spec, cfg: spec.n,
        loss=lambda spec, cfg, out, actions: losses.cross_entropy(out, actions),
        act=_categorical_act),
}
POLICIES = tuple(sorted({policy for policy, _ in HEADS}))
AUGMENTATIONS = ("none", "rotate90")


def head_for(policy: str, spec: Spec) -> Head:
    """The head of ``policy`` for actions of ``spec``; a clear error for unsupported pairs."""
    networks.check_supported(spec, "bc")
    head = HEADS.get((policy, type(spec)))
    if head is None:
        valid = [p for p, kind in HEADS if kind is type(spec)]
        raise ConfigError(f"bc: policy {policy!r} does not support {type(spec).__name__} actions; valid for "
                          f"{spec!r}: {valid}")
    return head


# ---------------------------------------------------------------------------------------------- states
@struct.dataclass
class BCState:
    """Acting state: shared parameters and observation statistics; ``deterministic`` selects eval mode."""

    params: PyTree
    observation_stats: normalizer.RunningStatistics
    spec: ArenaSpec = struct.field(pytree_node=False)
    deterministic: bool = struct.field(pytree_node=False, default=True)


@struct.dataclass
class BCTrainState:
    """Everything a run needs to continue bit for bit.

    ``data`` holds the dataset in its stored layout: ``observation`` (dict of (sum T_i + 1, ...), each
    trajectory's T_i + 1 observations end to end), ``action`` ((sum T_i, *shape)) and ``goal`` (dict of
    (N, ...)); ``lengths`` is int32 (N,), the T_i.
    """

    params: PyTree
    opt_state: PyTree
    observation_stats: normalizer.RunningStatistics
    data: PyTree
    lengths: jax.Array
    key: jax.Array
    update: jax.Array  # int32, updates done


def flatten(observation: dict, goal: dict, images: tuple[str, ...] = ()):
    """Observation fields (sorted by name) then goal fields, each flattened after axis 0: float32 (S, D).

    The same vector as :func:`jarena_agents.networks.flatten_observation` gives for an ``Info``. With image
    keys ``images``, :func:`jarena_agents.networks.split_observation`'s dict: those fields apart, the rest flat.
    """
    rest = {k: v for k, v in observation.items() if k not in images}
    leaves = jax.tree_util.tree_leaves(rest) + jax.tree_util.tree_leaves(goal)
    size = observation[next(iter(observation))].shape[0] if observation else 0
    vector = jnp.concatenate([jnp.zeros((size, 0), jnp.float32)]
                             + [x.reshape(x.shape[:1] + (-1,)).astype(jnp.float32) for x in leaves], axis=-1)
    return {"vector": vector, "images": {k: observation[k] for k in images}} if images else vector


# ---------------------------------------------------------------------------------------------- the dataset
def read_dataset(path: str, arena: Arena, chunk: int) -> dict[str, Any]:
    """The whole dataset at ``path`` as numpy arrays: ``data`` (see :class:`BCTrainState`), ``lengths``,
    and ``mean`` / ``var`` of the flattened observations (float32 (D,))."""
    if not path:
        raise ValueError("bc needs demonstrations: set its config key dataset=PATH to a TrajectoryDataset "
                         "(collect one with `jarena collect AGENT ARENA --out PATH`)")
    read = read_steps(path, arena, "bc")
    lengths = read["lengths"]
    if lengths.max() < chunk:
        raise DatasetError(f"bc: chunk={chunk} needs trajectories of at least {chunk} steps; the longest in "
                           f"{path!r} has {lengths.max()}")
    n, steps = len(lengths), int(lengths.sum())
    observation, goal = read["observation"], read["goal"]
    (action,) = read["action"].values()
    row_goal = {k: np.repeat(v, lengths + 1, axis=0) for k, v in goal.items()}
    images = networks.image_keys(arena.spec)  # not standardised: the CNN scales them
    vector = {k: v for k, v in observation.items() if k not in images}
    flat = np.concatenate([np.zeros((steps + n, 0))] + [x.reshape(x.shape[0], -1).astype(np.float64)
                           for x in jax.tree_util.tree_leaves(vector) + jax.tree_util.tree_leaves(row_goal)], -1)
    return dict(data=dict(observation=observation, action=action, goal=goal), lengths=lengths.astype(np.int32),
                mean=flat.mean(0).astype(np.float32), var=np.maximum(flat.var(0), MIN_VARIANCE).astype(np.float32))


def sample(data: dict, lengths: jax.Array, key: jax.Array, batch_size: int, chunk: int) -> tuple[jax.Array, dict]:
    """A minibatch drawn uniformly among the K-step windows of the trajectories.

    Returns ``(observation, goal, actions)``: the window's first observation (dict of (S, ...)), its
    trajectory's goal (dict of (S, ...)) and its K actions ((S, K, *shape)).
    """
    rank, step, _ = draw_indices(key, lengths, "window", batch_size, chunk)
    step_start = jnp.cumsum(lengths) - lengths  # first action row of each trajectory
    action_rows = step_start[rank] + step  # (S, K)
    observation_rows = action_rows[:, 0] + rank[:, 0]  # trajectory i's observations start at row step_start[i] + i
    observation = {k: v[observation_rows] for k, v in data["observation"].items()}
    goal = {k: v[rank[:, 0]] for k, v in data["goal"].items()}
    return observation, goal, data["action"][action_rows]


# ---------------------------------------------------------------------------------------------- the agent
def make_bc(config=None) -> TrainableAgent:
    cfg = make_config(BCConfig, config, agent="bc")
    if cfg.policy not in POLICIES:
        raise ConfigError(f"bc: unknown policy {cfg.policy!r}; valid policies: {list(POLICIES)}")
    if cfg.augment not in AUGMENTATIONS:
        raise ConfigError(f"bc: unknown augment {cfg.augment!r}; choose from {list(AUGMENTATIONS)}")
    if cfg.cnn_output not in networks.ENCODER_OUTPUTS:
        raise ConfigError(f"bc: unknown cnn_output {cfg.cnn_output!r}; choose from {list(networks.ENCODER_OUTPUTS)}")
    if cfg.cnn_padding not in networks.PADDINGS:
        raise ConfigError(f"bc: unknown cnn_padding {cfg.cnn_padding!r}; choose from {list(networks.PADDINGS)}")

    def network(spec: ArenaSpec):
        head = head_for(cfg.policy, spec.action)
        features = cfg.chunk * head.features(spec.action, cfg)
        if networks.image_keys(spec):
            return head, networks.EncodedMLP(tuple(cfg.hidden), features, tuple(tuple(c) for c in cfg.cnn),
                                             cfg.cnn_padding, cnn_output=cfg.cnn_output)
        return head, networks.MLP(tuple(cfg.hidden), features)

    def observe(spec: ArenaSpec, info: Info):
        """The network's input: the flat observation vector, or with image keys the vector and the images."""
        images = networks.image_keys(spec)
        return networks.split_observation(info, images) if images else networks.flatten_observation(info)

    def forward(spec: ArenaSpec, params, stats, observation):
        """Outputs (..., K, F) for flattened observations (..., D), or ``split_observation``'s dict of them."""
        if cfg.normalize_observations:
            if isinstance(observation, dict):
                observation = dict(observation, vector=normalizer.normalize(stats, observation["vector"]))
            else:
                observation = normalizer.normalize(stats, observation)
        _, mlp = network(spec)
        out = mlp.apply(params, observation)
        return out.reshape(out.shape[:-1] + (cfg.chunk, -1))

    def optimizer():
        lr = optax.cosine_decay_schedule(cfg.learning_rate, cfg.num_updates) if cfg.anneal_lr else cfg.learning_rate
        clip = optax.clip_by_global_norm(cfg.max_grad_norm) if cfg.max_grad_norm > 0 else optax.identity()
        return optax.chain(clip, optax.adam(lr))

    def init(key, spec: ArenaSpec, num_arenas: int) -> BCState:
        images = networks.image_keys(spec)
        dim = networks.vector_size(spec, images)
        example = jnp.zeros((1, dim), jnp.float32)
        if images:
            example = {"vector": example, "images": {k: spec.observation[k].zeros()[None] for k in images}}
        _, mlp = network(spec)
        return BCState(params=mlp.init(key, example), observation_stats=normalizer.init(dim), spec=spec)

    def act(state: BCState, info: Info, key, privileged=None):
        out = forward(state.spec, state.params, state.observation_stats, observe(state.spec, info))
        head, _ = network(state.spec)
        return head.act(state.spec.action, cfg, out[..., 0, :], key, state.deterministic), state

    def init_training(key, arena: Arena) -> BCTrainState:
        if cfg.augment == "rotate90":
            augment.check_rotate90(arena.spec, "bc")
        host = read_dataset(cfg.dataset, arena, cfg.chunk)
        device = to_device(host)
        key, init_key = jax.random.split(key)
        acting = init(init_key, arena.spec, 1)
        stats = normalizer.RunningStatistics(count=jnp.asarray(host["lengths"].sum() + host["lengths"].size,
                                                               jnp.float32),
                                             mean=device["mean"], var=device["var"])
        return BCTrainState(params=acting.params, opt_state=optimizer().init(acting.params), observation_stats=stats,
                            data=device["data"], lengths=device["lengths"], key=key, update=jnp.zeros((), jnp.int32))

    def policy(train_state: BCTrainState, spec: ArenaSpec, deterministic: bool = True) -> BCState:
        """The acting state of a trained agent (eval mode is deterministic)."""
        return BCState(params=train_state.params, observation_stats=train_state.observation_stats, spec=spec,
                       deterministic=deterministic)

    def one_update(spec: ArenaSpec, ts: BCTrainState):
        head, _ = network(spec)
        key, sample_key = jax.random.split(ts.key)
        observation, goal, actions = sample(ts.data, ts.lengths, sample_key, cfg.batch_size, cfg.chunk)
        # trained on a mesh: each device computes the loss of its share of the minibatch
        observation, goal, actions = distributed.split_batch((observation, goal, actions))
        if cfg.augment == "rotate90":
            key, turn_key = jax.random.split(key)
            images = networks.image_keys(spec)
            turned, points = augment.random_rotate90(turn_key, {k: observation[k] for k in images},
                                                     actions.reshape(actions.shape[:2] + (-1, 2)))
            observation, actions = dict(observation, **turned), points.reshape(actions.shape).astype(actions.dtype)
        inputs = flatten(observation, goal, networks.image_keys(spec))

        def loss_fn(params):
            return head.loss(spec.action, cfg, forward(spec, params, ts.observation_stats, inputs), actions)

        loss, grads = jax.value_and_grad(loss_fn)(ts.params)
        updates, opt_state = optimizer().update(grads, ts.opt_state, ts.params)
        ts = ts.replace(params=optax.apply_updates(ts.params, updates), opt_state=opt_state, key=key,
                        update=ts.update + 1)
        # No environment episodes finish while cloning: train_and_evaluate logs their return as nan.
        return ts, dict(loss=loss, episodes=jnp.zeros((), jnp.int32), episode_return=jnp.zeros((), jnp.float32))

    def train(train_state: BCTrainState, arena: Arena, num_updates: int):
        """Runs ``num_updates`` gradient steps (static) in one ``lax.scan``; metrics have a leading update axis."""
        return jax.lax.scan(lambda ts, _: one_update(arena.spec, ts), train_state, None, length=num_updates)

    agent = Agent(name="bc", init=init, act=act, config=dataclasses.asdict(cfg))
    return TrainableAgent.wrap(agent, init_training=init_training, train=train, policy=policy, settings=cfg)


register_agent("bc", make_bc, tags=("trainable", "imitation"))
