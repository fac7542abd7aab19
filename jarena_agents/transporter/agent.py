"""Transporter Networks (Zeng et al., CoRL 2020) as a trainable jarena agent: pick-and-place from top-down images.

For arenas that observe a top-down colour image ``rgb`` uint8 (H, W, 3), with a height map ``height`` (H, W)
(metres) or a depth image ``depth`` (H, W) or neither, and act with one pick and one place in that image: float32
(5,) ``(pick_row, pick_col, place_row, place_col, place_yaw)`` in its pixels (rows 0 .. H - 1, columns 0 .. W - 1,
the yaw in radians; the Raven arenas, ``raven|task:block-insertion``), or float32 (4,) ``(pick_u, pick_v, place_u,
place_v)``, normalised image points without a yaw (the cloth arenas' ``pixel_pick_and_place(1)``). How the image
and the action map onto the arena's is :mod:`jarena_agents.transporter.layout` (config key ``action_frame``).

Acting (:mod:`jarena_agents.transporter.networks`), per arena: the attention network scores every pixel as the
pick point and the best is picked; the transport network scores every pixel and each of ``rotations`` yaws (``k 2
pi / rotations``) as the place for that pick, by correlating the features of the scene with those of the turned
window of ``crop`` x ``crop`` pixels around the pick; the best is the place and its yaw. Both are argmaxes, so the
policy is deterministic (train and eval modes alike) and each arena's action depends on its own image alone.

Training reads a :class:`~jarena.data.dataset.TrajectoryDataset` (config key ``dataset``, e.g. collected with
``jarena collect oracle_raven ...`` or ``jarena collect oracle_cloth_flattening ...``) whole into device memory, as
``bc`` does, its actions turned into pick and place pixels and a yaw; each update draws ``batch_size``
demonstrated steps uniformly, moves each image and its pick and place pixels by a random planar motion
(``augment``: :func:`jarena_agents.transporter.se2.augment`), and takes one Adam step on the sum of two
cross-entropies: the attention's softmax over the pixels against the demonstrated pick pixel, and the transport's
softmax over pixels and yaws, at the demonstrated pick, against the demonstrated place pixel and nearest yaw. A
"step" of ``total_steps`` is one gradient update. On a mesh of devices each computes its share of the batch.

Defaults are the paper's: Ravens' ``ResNet43_8s`` (``widths`` 64, 128, 256, 512, a head of 16; stride 8), one
attention channel and 3 transport features, 64 x 64 crops, 36 yaws, Adam at 1e-4, 40,000 updates of one
demonstration each with augmentation.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import optax
from flax import struct

from jarena import distributed
from jarena.core.agent import Agent
from jarena.core.arena import Arena, ArenaSpec
from jarena.core.types import Info
from jarena_agents.config import ConfigError, DatasetSchedule, at_least, make_config, positive
from jarena_agents.datasets import to_device
from jarena_agents.networks import init_params
from jarena_agents.registry import register_agent
from jarena_agents.trainable import TrainableAgent
from jarena_agents.transporter import data, se2
from jarena_agents.transporter import layout as layout_lib
from jarena_agents.transporter.layout import COLOR_KEY, FRAMES, Layout
from jarena_agents.transporter.networks import CHANNELS, FCN, attention_logits, raw_input, transport_logits

PyTree = Any


@dataclasses.dataclass(frozen=True)
class TransporterConfig(DatasetSchedule):
    """Transporter hyperparameters.

    Attributes:
      dataset: path of the TrajectoryDataset of demonstrations (needed for training, not for acting).
      widths: the fully convolutional ResNet's stage widths (:class:`jarena_agents.transporter.networks.FCN`): its
        stride is ``2^(len(widths) - 1)``.
      head: width of its output stage.
      transport_features: channels of the transport's key and query features.
      crop: side of the window around the pick that the query network sees, pixels (even).
      rotations: yaws the transport scores, ``k 2 pi / rotations`` (radians).
      batch_size: demonstrated steps per gradient update.
      learning_rate: Adam's step size.
      total_steps: gradient updates of a run.
      augment: move each demonstration by a random planar motion (image and pick and place pixels together).
      action_frame: what the arena's action is (:data:`jarena_agents.transporter.layout.FRAMES`): ``auto`` (read
        from its action spec), ``pixels`` (pick and place pixels and a yaw) or ``image_points`` (pick and place
        ``(u, v)`` in [-1, 1], no yaw: ``rotations`` must be 1).
    """

    dataset: str = ""
    widths: tuple = (64, 128, 256, 512)
    head: int = at_least(1, default=16)
    transport_features: int = at_least(1, default=3)
    crop: int = at_least(2, default=64)
    rotations: int = at_least(1, default=36)
    batch_size: int = at_least(1, default=1)
    learning_rate: float = positive(1e-4)
    total_steps: int = at_least(1, default=40_000)
    augment: bool = True
    action_frame: str = "auto"


def check_config(cfg: TransporterConfig) -> None:
    """Raises a ``ConfigError`` naming what is wrong with ``widths`` or ``crop`` (each field's own range is checked by
    :func:`jarena_agents.config.make_config`)."""
    widths = tuple(cfg.widths)
    if not widths or any(isinstance(w, bool) or not isinstance(w, int) or w < 1 for w in widths):
        raise ConfigError(f"transporter: widths must be a non-empty list of positive integers, got {list(widths)}")
    if cfg.crop % 2:
        raise ConfigError(f"transporter: crop must be even (the pick point is the crop's middle pixel once padded to "
                          f"an odd kernel), got {cfg.crop}")
    if cfg.action_frame not in FRAMES:
        raise ConfigError(f"transporter: unknown action_frame {cfg.action_frame!r}; choose from {list(FRAMES)}")


def check_spec(spec: ArenaSpec, cfg: TransporterConfig) -> Layout:
    """The arena's :class:`~jarena_agents.transporter.layout.Layout` for ``cfg``; a ``ConfigError`` unless it
    observes ``rgb`` uint8 (H, W, 3) (and ``height`` or ``depth`` (H, W), if either) and acts with pick and place
    pixels and a yaw, or with pick and place image points (then ``rotations`` must be 1)."""
    return layout_lib.layout_of(spec, cfg.action_frame, cfg.rotations)


# ---------------------------------------------------------------------------------------------- states
@struct.dataclass
class TransporterState:
    """Acting state: the parameters (``{"attention", "key", "query"}``). ``deterministic`` changes nothing: the
    policy is an argmax in both modes."""

    params: PyTree
    spec: ArenaSpec = struct.field(pytree_node=False)
    deterministic: bool = struct.field(pytree_node=False, default=True)


@struct.dataclass
class TransporterTrainState:
    """Everything a run needs to continue bit for bit. ``data``: :func:`jarena_agents.transporter.data.read_dataset`'s
    arrays (``rgb``, ``height``, ``action``) on the device."""

    params: PyTree
    opt_state: PyTree
    data: PyTree
    key: jax.Array
    update: jax.Array  # int32, updates done


def labels(action: jax.Array, shape: tuple[int, int], rotations: int) -> tuple[jax.Array, jax.Array, jax.Array]:
    """A demonstrated action (5,)'s pick and place pixels (int32 (2,) each, rounded into the image) and yaw bin."""
    upper = jnp.asarray([shape[0] - 1, shape[1] - 1])
    pick, place = (jnp.clip(jnp.round(action[i:i + 2]).astype(jnp.int32), 0, upper) for i in (0, 2))
    return pick, place, se2.yaw_bins(action[4], rotations)


# ---------------------------------------------------------------------------------------------- the model
class Model(NamedTuple):
    """Transporter's pure functions for one config; images are :func:`~jarena_agents.transporter.networks.raw_input`
    arrays (H, W, 6), one demonstration or arena at a time (callers vmap and jit).

    Attributes:
      init: ``key -> params``, ``{"attention", "key", "query"}``.
      logits: ``(params, image, pick (2,)) -> (pick logits (H, W), place logits (H, W, R))``.
      choose: ``(params, image) -> action (5,)``: the argmax pick, then the argmax place and yaw for it.
      losses: ``(params, image, action (5,)) -> (attention, transport)``: the demonstration's cross-entropies.
      start: ``(key, data) -> TransporterTrainState`` for :func:`jarena_agents.transporter.data.read_dataset`'s
        arrays (on the device).
      update: ``train_state -> (train_state, metrics)``: one gradient step on a batch drawn from its data.
    """

    init: Callable
    logits: Callable
    choose: Callable
    losses: Callable
    start: Callable
    update: Callable


def build_model(cfg: TransporterConfig) -> Model:
    """The :class:`Model` of ``cfg`` (checked by :func:`check_config`)."""
    widths = tuple(cfg.widths)
    attention = FCN(widths, cfg.head, 1)
    key_net = FCN(widths, cfg.head, cfg.transport_features)
    query_net = FCN(widths, cfg.head, cfg.transport_features)
    yaws = se2.bin_yaws(cfg.rotations)
    optimizer = optax.adam(cfg.learning_rate, eps=1e-7)  # Keras' Adam, as Ravens trains

    def init(key) -> dict:
        example = jnp.zeros((1, attention.stride, attention.stride, CHANNELS), jnp.float32)
        keys = jax.random.split(key, 3)
        return {name: init_params(net, k, example)
                for name, net, k in zip(("attention", "key", "query"), (attention, key_net, query_net), keys,
                                        strict=True)}

    def place_logits(params, image, pick):
        return transport_logits(key_net, query_net, params["key"], params["query"], image, pick, yaws, cfg.crop)

    def logits(params, image: jax.Array, pick: jax.Array) -> tuple[jax.Array, jax.Array]:
        return attention_logits(attention, params["attention"], image), place_logits(params, image, pick)

    def choose(params, image: jax.Array) -> jax.Array:
        width = image.shape[1]
        index = jnp.argmax(attention_logits(attention, params["attention"], image).reshape(-1))
        pick = jnp.stack([index // width, index % width])
        index = jnp.argmax(place_logits(params, image, pick).reshape(-1))
        place = jnp.stack([index // (width * cfg.rotations), (index // cfg.rotations) % width])
        return jnp.concatenate([pick.astype(jnp.float32), place.astype(jnp.float32), yaws[index % cfg.rotations][None]])

    def losses(params, image: jax.Array, action: jax.Array) -> tuple[jax.Array, jax.Array]:
        shape = image.shape[:2]
        pick, place, turn = labels(action, shape, cfg.rotations)
        pick_logits, to_place = logits(params, image, pick)
        attention_loss = -jax.nn.log_softmax(pick_logits.reshape(-1))[pick[0] * shape[1] + pick[1]]
        target = (place[0] * shape[1] + place[1]) * cfg.rotations + turn
        return attention_loss, -jax.nn.log_softmax(to_place.reshape(-1))[target]

    def start(key, data: dict) -> TransporterTrainState:
        key, init_key = jax.random.split(key)
        params = init(init_key)
        return TransporterTrainState(params=params, opt_state=optimizer.init(params), data=data, key=key,
                                     update=jnp.zeros((), jnp.int32))

    def draw(data: dict, key) -> tuple[jax.Array, jax.Array]:
        """``batch_size`` demonstrated steps drawn uniformly: images (S, H, W, 6) and actions (S, 5), each moved by
        a random planar motion with ``augment``."""
        sample_key, augment_key = jax.random.split(key)
        index = jax.random.randint(sample_key, (cfg.batch_size,), 0, data["action"].shape[0])
        images, actions = raw_input(data["rgb"][index], data["height"][index]), data["action"][index]
        if not cfg.augment:
            return images, actions

        def move(k, image, action):
            image, points = se2.augment(k, image, action[:4].reshape(2, 2))
            return image, jnp.concatenate([points.reshape(4), action[4:]])

        return jax.vmap(move)(jax.random.split(augment_key, cfg.batch_size), images, actions)

    def update(ts: TransporterTrainState):
        key, draw_key = jax.random.split(ts.key)
        images, actions = draw(ts.data, draw_key)
        # trained on a mesh: each device computes the losses of its share of the batch
        images, actions = distributed.split_batch((images, actions))

        def loss_fn(params):
            attention_loss, transport_loss = jax.vmap(lambda i, a: losses(params, i, a))(images, actions)
            return jnp.mean(attention_loss + transport_loss), (jnp.mean(attention_loss), jnp.mean(transport_loss))

        (loss, (attention_loss, transport_loss)), grads = jax.value_and_grad(loss_fn, has_aux=True)(ts.params)
        updates, opt_state = optimizer.update(grads, ts.opt_state, ts.params)
        ts = ts.replace(params=optax.apply_updates(ts.params, updates), opt_state=opt_state, key=key,
                        update=ts.update + 1)
        # No environment episodes finish while training from demonstrations: train_and_evaluate logs nan returns.
        return ts, dict(loss=loss, attention_loss=attention_loss, transport_loss=transport_loss,
                        episodes=jnp.zeros((), jnp.int32), episode_return=jnp.zeros((), jnp.float32))

    return Model(init=init, logits=logits, choose=choose, losses=losses, start=start, update=update)


# ---------------------------------------------------------------------------------------------- the agent
def make_transporter(config=None) -> TrainableAgent:
    """Transporter Networks: pick by attention, place by correlating turned crops of the pick with the scene."""
    cfg = make_config(TransporterConfig, config, agent="transporter")
    check_config(cfg)
    model = build_model(cfg)

    def init(key, spec: ArenaSpec, num_arenas: int) -> TransporterState:
        check_spec(spec, cfg)
        return TransporterState(params=model.init(key), spec=spec)

    def act(state: TransporterState, info: Info, key, privileged=None):
        batch = info.step.shape
        layout = check_spec(state.spec, cfg)
        images = raw_input(info.observation[COLOR_KEY], layout_lib.height_map(info.observation, layout))
        actions = jax.vmap(lambda image: model.choose(state.params, image))(images.reshape((-1,) + images.shape[-3:]))
        actions = layout_lib.to_arena_action(actions, layout)
        spec = state.spec.action
        actions = jnp.clip(actions, jnp.asarray(spec.low, jnp.float32), jnp.asarray(spec.high, jnp.float32))
        return actions.reshape(batch + (layout.action_size,)).astype(spec.dtype), state

    def init_training(key, arena: Arena) -> TransporterTrainState:
        layout = check_spec(arena.spec, cfg)
        layout_lib.check_tool(getattr(arena.tool, "name", ""), layout, cfg.action_frame)
        return model.start(key, to_device(data.read_dataset(cfg.dataset, arena, layout)))

    def policy(train_state: TransporterTrainState, spec: ArenaSpec, deterministic: bool = True) -> TransporterState:
        """The acting state of a trained agent."""
        return TransporterState(params=train_state.params, spec=spec, deterministic=deterministic)

    def train(train_state: TransporterTrainState, arena: Arena, num_updates: int):
        """Runs ``num_updates`` gradient steps (static) in one ``lax.scan``; metrics have a leading update axis."""
        return jax.lax.scan(lambda ts, _: model.update(ts), train_state, None, length=num_updates)

    agent = Agent(name="transporter", init=init, act=act, config=dataclasses.asdict(cfg))
    return TrainableAgent.wrap(agent, init_training=init_training, train=train, policy=policy, settings=cfg)


register_agent("transporter", make_transporter, tags=("trainable", "imitation"))
