"""Flax networks for agents: observation flattening, MLP torsos and policy distributions."""

from __future__ import annotations

from collections.abc import Sequence

import flax.linen as nn
import flax.struct
import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.arena import ArenaSpec
from jarena.core.spec import Box, Discrete, Spec
from jarena.core.types import Info


def observation_size(spec: ArenaSpec) -> int:
    """Length of :func:`flatten_observation`'s output for an arena of ``spec``."""
    return vector_size(spec, ())


def flatten_observation(info: Info, batch_dims: int = 1) -> jax.Array:
    """Concatenates every observation leaf (sorted by key) and the goal into float32 (*batch, D)."""
    leaves = jax.tree_util.tree_leaves(info.observation) + [info.goal]
    batch = leaves[0].shape[:batch_dims]
    return jnp.concatenate([x.reshape(batch + (-1,)).astype(jnp.float32) for x in leaves], axis=-1)


def image_keys(spec: ArenaSpec) -> tuple[str, ...]:
    """Observation keys that hold images: uint8 ``Box`` entries of shape (H, W, C), sorted."""
    spaces = getattr(spec.observation, "spaces", {})
    return tuple(sorted(k for k, s in spaces.items()
                        if isinstance(s, Box) and s.dtype == np.uint8 and len(s.shape) == 3))


def vector_size(spec: ArenaSpec, images: tuple[str, ...]) -> int:
    """Length of :func:`split_observation`'s vector: every observation leaf but ``images``, and the goal."""
    zeros = spec.observation.zeros()
    if images:
        zeros = {k: v for k, v in zeros.items() if k not in images}
    return int(sum(np.prod(x.shape, dtype=int) for x in jax.tree_util.tree_leaves(zeros))) + spec.goal_dim


def split_observation(info: Info, images: tuple[str, ...], batch_dims: int = 1) -> dict:
    """``{"vector": float32 (*batch, D), "images": {key: uint8 (*batch, H, W, C)}}``: the image keys apart, every
    other leaf (sorted by key) and the goal flattened as :func:`flatten_observation` does."""
    rest = {k: v for k, v in info.observation.items() if k not in images}
    vector = flatten_observation(info.replace(observation=rest), batch_dims)
    return {"vector": vector, "images": {k: info.observation[k] for k in images}}


#: Convolution paddings by config name.
PADDINGS = ("VALID", "SAME")


class PixelEncoder(nn.Module):
    """A convolutional torso for uint8 images: each key's (*, H, W, C) image scaled to [-0.5, 0.5], through
    ``layers`` of ``(features, kernel, stride)`` ReLU convolutions, flattened; the keys' features concatenated
    (sorted by key). Defaults: the Nature DQN's layers and padding ('VALID': 64 x 64 -> 4 x 4 x 64 features;
    'SAME' keeps ceil(H / stride)). With ``output="spatial_softmax"`` each of the last layer's C feature maps
    becomes the expected image point ``(u, v)`` in [-1, 1] of its softmax over the pixels (Levine et al. 2016's
    keypoints, robomimic's visual encoder): 2 C features that say *where*, for policies that output image
    points."""

    layers: Sequence[tuple[int, int, int]] = ((32, 8, 4), (64, 4, 2), (64, 3, 1))
    padding: str = "VALID"
    output: str = "flatten"

    @nn.compact
    def __call__(self, images: dict) -> jax.Array:
        if self.output not in ENCODER_OUTPUTS:
            raise ValueError(f"unknown PixelEncoder output {self.output!r}; choose from {', '.join(ENCODER_OUTPUTS)}")
        out = []
        for key in sorted(images):
            x = images[key]
            batch = x.shape[:-3]
            x = x.reshape((-1,) + x.shape[-3:]).astype(jnp.float32) / 255.0 - 0.5
            for i, (features, kernel, stride) in enumerate(self.layers):
                if self.padding == "VALID" and min(x.shape[1:3]) < kernel:
                    raise ValueError(f"image {key!r}: layer {i}'s {kernel} x {kernel} kernel does not fit its "
                                     f"{x.shape[1]} x {x.shape[2]} input with 'VALID' padding; use smaller kernels "
                                     f"or strides, or padding 'SAME'")
                x = nn.relu(nn.Conv(features, (kernel, kernel), (stride, stride), padding=self.padding,
                                    kernel_init=nn.initializers.orthogonal(np.sqrt(2)), name=f"{key}_conv{i}")(x))
            out.append(ENCODER_OUTPUTS[self.output](x).reshape(batch + (-1,)))
        return jnp.concatenate(out, axis=-1)


def encode_images(x, cnn: Sequence[tuple[int, int, int]], padding: str, output: str = "flatten") -> jax.Array:
    """Inside a compact module: a float (*, D) vector as it is, or :func:`split_observation`'s dict as its vector
    joined with its images' :class:`PixelEncoder` features (a submodule named ``encoder``)."""
    if not isinstance(x, dict):
        return x
    features = PixelEncoder(tuple(cnn), padding, output, name="encoder")(x["images"])
    return jnp.concatenate([x["vector"], features], axis=-1)


def spatial_softmax(features: jax.Array) -> jax.Array:
    """Feature maps (N, H, W, C) -> float32 (N, C, 2): each channel's expected pixel centre ``(u, v)``
    (normalised image coordinates in [-1, 1], u along the width) under its softmax over the H x W pixels."""
    n, h, w, c = features.shape
    weights = jax.nn.softmax(features.reshape(n, h * w, c).astype(jnp.float32), axis=1).reshape(n, h, w, c)
    u = (jnp.arange(w, dtype=jnp.float32) + 0.5) / (w / 2) - 1.0
    v = (jnp.arange(h, dtype=jnp.float32) + 0.5) / (h / 2) - 1.0
    return jnp.stack([jnp.einsum("nhwc,w->nc", weights, u), jnp.einsum("nhwc,h->nc", weights, v)], axis=-1)


#: PixelEncoder outputs by config name: the last feature maps (N, H, W, C) -> features (N, ...).
ENCODER_OUTPUTS = {"flatten": lambda maps: maps, "spatial_softmax": spatial_softmax}


#: Hidden-layer activations by config name (Brax's PPO networks use swish).
ACTIVATIONS = {"tanh": nn.tanh, "relu": nn.relu, "swish": nn.swish}


class MLP(nn.Module):
    """``hidden`` layers (``activation``, one of ``ACTIVATIONS``) then a linear output of ``features``
    (orthogonal initialisation)."""

    hidden: Sequence[int]
    features: int
    output_scale: float = 1.0
    activation: str = "tanh"

    @nn.compact
    def __call__(self, x):
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"unknown activation {self.activation!r}; choose from {', '.join(ACTIVATIONS)}")
        activation = ACTIVATIONS[self.activation]
        for width in self.hidden:
            x = activation(nn.Dense(width, kernel_init=nn.initializers.orthogonal(np.sqrt(2)))(x))
        return nn.Dense(self.features, kernel_init=nn.initializers.orthogonal(self.output_scale))(x)


class EncodedMLP(nn.Module):
    """An :class:`MLP` over a float (*, D) vector or :func:`split_observation`'s dict, whose images go through a
    :class:`PixelEncoder` (``cnn`` layers, ``cnn_padding``) and join the vector first. Returns (*, features)."""

    hidden: Sequence[int]
    features: int
    cnn: Sequence[tuple[int, int, int]] = PixelEncoder.layers
    cnn_padding: str = PixelEncoder.padding
    activation: str = "tanh"
    cnn_output: str = PixelEncoder.output

    @nn.compact
    def __call__(self, x):
        x = encode_images(x, self.cnn, self.cnn_padding, self.cnn_output)
        return MLP(self.hidden, self.features, activation=self.activation, name="mlp")(x)


@flax.struct.dataclass
class Gaussian:
    """A diagonal Gaussian over raw actions (*, d) in normalised units; the arena gets them clipped to
    [-1, 1] and rescaled (:func:`to_env_action`). Entropy and log-probabilities are the Gaussian's."""

    mean: jax.Array
    log_std: jax.Array

    def sample(self, key):
        return self.mean + jnp.exp(self.log_std) * jax.random.normal(key, self.mean.shape)

    def mode(self):
        return self.mean

    def log_prob(self, raw):
        z = (raw - self.mean) / jnp.exp(self.log_std)
        return jnp.sum(-0.5 * z**2 - self.log_std - 0.5 * jnp.log(2 * jnp.pi), -1)

    def entropy(self):
        return jnp.sum(self.log_std + 0.5 * jnp.log(2 * jnp.pi * jnp.e), -1)

    def unit(self, raw):
        """The action in [-1, 1]."""
        return jnp.clip(raw, -1.0, 1.0)


@flax.struct.dataclass
class TanhNormal:
    """``tanh(u)`` with ``u ~ N(mean, std)`` (Brax's PPO policy). Raw actions are the pre-tanh ``u``, so
    log-probabilities need no ``atanh``: ``log N(u) - sum log(1 - tanh(u)^2)``. The entropy is the
    Gaussian's plus that log-determinant at the mode ``tanh(mean)`` (Brax estimates it at a sample)."""

    mean: jax.Array
    std: jax.Array

    def sample(self, key):
        return self.mean + self.std * jax.random.normal(key, self.mean.shape)

    def mode(self):
        return self.mean

    def _base(self) -> Gaussian:
        return Gaussian(self.mean, jnp.log(self.std))

    def log_prob(self, raw):
        return self._base().log_prob(raw) - jnp.sum(_log_tanh_derivative(raw), -1)

    def entropy(self):
        return self._base().entropy() + jnp.sum(_log_tanh_derivative(self.mean), -1)

    def unit(self, raw):
        return jnp.tanh(raw)


def _log_tanh_derivative(u):
    """``log(1 - tanh(u)^2)``, stably: ``2 (log 2 - u - softplus(-2 u))``."""
    return 2.0 * (jnp.log(2.0) - u - jax.nn.softplus(-2.0 * u))


#: Policy distributions for Box actions, by config name.
BOX_POLICIES = ("gaussian", "tanh_normal")


class ActorCritic(nn.Module):
    """Separate policy and value MLPs. Returns ``(policy, value)``.

    Policy: logits (*, n) for Discrete actions; for Box actions a :class:`Gaussian` (mean from the MLP,
    learned state-independent log standard deviation) or, with ``box_policy="tanh_normal"``, a
    :class:`TanhNormal` (mean and ``softplus(.) + min_std`` from the MLP, as Brax's PPO).
    ``value_hidden`` sizes the value MLP (default: ``hidden``); ``activation`` names both MLPs'.
    Input: a float (*, D) vector, or :func:`split_observation`'s dict, whose images go through a shared
    :class:`PixelEncoder` (``cnn`` layers, ``cnn_padding``) and join the vector before both MLPs.
    """

    action_spec: Spec
    hidden: Sequence[int] = (64, 64)
    value_hidden: Sequence[int] | None = None
    box_policy: str = "gaussian"
    min_std: float = 1e-3
    activation: str = "tanh"
    cnn: Sequence[tuple[int, int, int]] = PixelEncoder.layers
    cnn_padding: str = PixelEncoder.padding

    @nn.compact
    def __call__(self, x):
        x = encode_images(x, self.cnn, self.cnn_padding)  # one CNN torso shared by both MLPs
        value_hidden = self.hidden if self.value_hidden is None else self.value_hidden
        value = MLP(value_hidden, 1, output_scale=1.0, activation=self.activation, name="critic")(x)[..., 0]
        if isinstance(self.action_spec, Discrete):
            return MLP(self.hidden, self.action_spec.n, output_scale=0.01, activation=self.activation,
                       name="actor")(x), value
        if self.box_policy not in BOX_POLICIES:
            raise ValueError(f"unknown box_policy {self.box_policy!r}; choose from {', '.join(BOX_POLICIES)}")
        dim = int(np.prod(self.action_spec.shape))
        if self.box_policy == "tanh_normal":
            out = MLP(self.hidden, 2 * dim, output_scale=0.01, activation=self.activation, name="actor")(x)
            return TanhNormal(out[..., :dim], jax.nn.softplus(out[..., dim:]) + self.min_std), value
        mean = MLP(self.hidden, dim, output_scale=0.01, activation=self.activation, name="actor")(x)
        log_std = self.param("log_std", nn.initializers.zeros, (dim,))
        return Gaussian(mean, jnp.broadcast_to(log_std, mean.shape)), value


def check_supported(spec: Spec, agent: str) -> None:
    if isinstance(spec, Discrete):
        return
    if isinstance(spec, Box) and spec.bounded and spec.dtype.kind == "f":
        return
    raise TypeError(f"{agent} supports Discrete or bounded float Box actions, got {spec!r}")


def sample_action(spec: Spec, policy, key, deterministic: bool):
    """Samples (or takes the mode of) the policy; returns ``(raw action, log prob, entropy)``.

    For Box actions the raw action is in the distribution's own units; :func:`to_env_action` maps it
    into the spec's bounds.
    """
    if isinstance(spec, Discrete):
        logits = policy
        action = jnp.argmax(logits, -1) if deterministic else jax.random.categorical(key, logits)
        return action.astype(jnp.int32), log_prob(spec, policy, action), entropy(spec, policy)
    action = policy.mode() if deterministic else policy.sample(key)
    return action, policy.log_prob(action), policy.entropy()


def log_prob(spec: Spec, policy, action):
    if isinstance(spec, Discrete):
        logp = jax.nn.log_softmax(policy)
        return jnp.take_along_axis(logp, action[..., None].astype(jnp.int32), -1)[..., 0]
    return policy.log_prob(action)


def entropy(spec: Spec, policy):
    if isinstance(spec, Discrete):
        logp = jax.nn.log_softmax(policy)
        return -jnp.sum(jnp.exp(logp) * logp, -1)
    return policy.entropy()


def to_env_action(spec: Spec, raw, policy=None):
    """Maps a raw policy action into the arena's action space (Box: into [-1, 1] by the policy's
    ``unit``, clipping when no policy is given, then rescaled to the bounds)."""
    if isinstance(spec, Discrete):
        return raw
    low, high = jnp.asarray(spec.low, jnp.float32), jnp.asarray(spec.high, jnp.float32)
    unit = jnp.clip(raw, -1.0, 1.0) if policy is None else policy.unit(raw)
    unit = unit.reshape(raw.shape[:-1] + spec.shape)
    return (low + (unit + 1.0) * 0.5 * (high - low)).astype(spec.dtype)


def init_params(module: nn.Module, key: jax.Array, *example) -> dict:
    """``module``'s parameters for inputs like ``example``: every kernel drawn from N(0, 1 / fan_in) (fan_in: the
    product of all but its last axis, LeCun's scaling), biases 0, normalisation scales 1.

    One normal draw serves every kernel, so the compiled initialiser stays small (flax's per-parameter truncated
    normals cost seconds of compilation on a CPU for a network of this many layers).
    """
    shapes = jax.eval_shape(module.init, jax.random.key(0), *example)
    leaves, treedef = jax.tree_util.tree_flatten_with_path(shapes)
    names = [str(getattr(path[-1], "key", path[-1])) for path, _ in leaves]
    sizes = [int(np.prod(leaf.shape, dtype=int)) if name == "kernel" else 0
             for name, (_, leaf) in zip(names, leaves, strict=True)]
    normal = jax.random.normal(key, (sum(sizes),), jnp.float32)
    out, start = [], 0
    for name, size, (_, leaf) in zip(names, sizes, leaves, strict=True):
        if name == "kernel":
            fan_in = int(np.prod(leaf.shape[:-1], dtype=int))
            out.append(normal[start:start + size].reshape(leaf.shape) / np.sqrt(fan_in))
            start += size
        else:
            out.append(jnp.full(leaf.shape, 1.0 if name == "scale" else 0.0, leaf.dtype))
    return jax.tree_util.tree_unflatten(treedef, out)
