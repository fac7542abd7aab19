"""Diffusion Policy's networks (Chi et al. 2023, CNN backbone), channels last.

- :class:`TemporalUnet`: the noise-prediction network, a 1-D U-Net over the action sequence (B, H, A). Each of
  its residual blocks is two (Conv1d, GroupNorm, Mish) layers, the first's output modulated by FiLM (a per-channel
  scale and bias predicted from the condition: the observation features and the sinusoidal embedding of the
  diffusion step).
- :class:`ImageEncoder`: a ResNet-18-like torso with GroupNorm instead of BatchNorm (an average of weights and
  batch statistics do not mix), then spatial-softmax keypoints and a linear layer.
- :class:`ObservationEncoder`: one image encoder per image key, features joined (sorted by key) with the
  normalised low-dimensional observation vector.
- :func:`crop`: the fixed-size crops the encoder sees (random in training, central when acting).
"""

from __future__ import annotations

from collections.abc import Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp

from jarena_agents.networks import init_params, spatial_softmax  # noqa: F401  (init_params: the agent reads it here)

GROUP_NORM_EPSILON = 1e-5


def unfold(x: jax.Array, size: Sequence[int], strides: Sequence[int], padding: Sequence[tuple[int, int]]) -> jax.Array:
    """The windows a convolution reads, side by side: (N, *spatial, C) -> (N, *out, prod(size) C). Unfolded one axis
    at a time (k_0 + k_1 slices for a 2-D window, not k_0 k_1), so the features are ordered (k_last, ..., k_first, C):
    ``windows @ kernel.transpose(last spatial axis first, ..., C, O).reshape(-1, O)`` convolves."""
    x = jnp.pad(x, ((0, 0),) + tuple(tuple(p) for p in padding) + ((0, 0),))
    for axis, (k, s) in enumerate(zip(size, strides, strict=True), start=1):
        out = (x.shape[axis] - k) // s + 1
        x = jnp.concatenate([jax.lax.slice_in_dim(x, o, o + (out - 1) * s + 1, s, axis=axis) for o in range(k)],
                            axis=-1)
    return x


def dilate(x: jax.Array, factor: int) -> jax.Array:
    """(N, L, C) -> (N, factor (L - 1) + 1, C): ``factor - 1`` zeros between consecutive steps."""
    n, length, channels = x.shape
    spread = jnp.zeros((n, length, factor, channels), x.dtype).at[:, :, 0].set(x)
    return spread.reshape(n, length * factor, channels)[:, :factor * (length - 1) + 1]


def convolve(x: jax.Array, kernel: jax.Array, strides: Sequence[int], padding: Sequence[tuple[int, int]],
             dilation: int = 1, method: str = "auto") -> jax.Array:
    """A convolution, channels last: ``x`` (N, *spatial, C), ``kernel`` (*size, C, O) -> (N, *out, O).

    ``dilation`` spreads the input first (``dilation - 1`` zeros between steps; 1-D). ``method``: ``"matmul"``, a
    matrix product over :func:`unfold` ed windows; ``"xla"``, XLA's convolution operator (cuDNN on a GPU); ``"auto"``
    (default), XLA's operator for 2-D convolutions off the CPU and the matrix product otherwise. XLA's CPU backend
    runs the gradients of its convolution operator 10 to 50 times slower inside a loop (the ``lax.scan`` of a
    training chunk) than outside it, where matrix products run at full speed. On an H200, XLA's operator made the
    image encoder's update faster (PushT from images: 7.9 against 9.6 ms) and the U-Net's 1-D one slower (PushT's
    keypoints: 7.0 against 6.4 ms; ``benchmarks/diffusion_step.py``). Both compute the same convolution, to float
    rounding.
    """
    if method not in ("auto", "matmul", "xla"):
        raise ValueError(f"convolution method {method!r}; valid: auto, matmul, xla")
    rank = kernel.ndim - 2
    if method == "auto":
        method = "xla" if rank >= 2 and jax.default_backend() != "cpu" else "matmul"
    if method == "xla":
        spatial = "DHW"[-rank:]
        numbers = (f"N{spatial}C", f"{spatial}IO", f"N{spatial}C")
        return jax.lax.conv_general_dilated(x, kernel.astype(x.dtype), tuple(strides), [tuple(p) for p in padding],
                                            lhs_dilation=(dilation,) * rank, dimension_numbers=numbers)
    if dilation > 1:
        x = dilate(x, dilation)
    order = tuple(reversed(range(rank))) + (rank, rank + 1)  # unfold's feature order
    return unfold(x, kernel.shape[:rank], strides, padding) @ kernel.transpose(order).reshape(-1, kernel.shape[-1])


class Conv(nn.Module):
    """A convolution, channels last, by :func:`convolve` (XLA's operator for 2-D convolutions off the CPU, a matrix
    product otherwise); kernel (*size, C, O). ``dilation`` spreads the input first (zeros between steps, 1-D): with
    ``padding`` (k - 1 - p) on each side, the transposed convolution that doubles a length.
    """

    features: int
    size: Sequence[int]
    strides: Sequence[int] | None = None
    padding: Sequence[tuple[int, int]] | None = None
    use_bias: bool = True
    dilation: int = 1

    @nn.compact
    def __call__(self, x):
        size = tuple(self.size)
        strides = tuple(self.strides or (1,) * len(size))
        padding = self.padding if self.padding is not None else [(0, 0)] * len(size)
        kernel = self.param("kernel", nn.initializers.lecun_normal(), size + (x.shape[-1], self.features))
        y = convolve(x, kernel, strides, padding, self.dilation)
        return y + self.param("bias", nn.initializers.zeros, (self.features,)) if self.use_bias else y


def mish(x: jax.Array) -> jax.Array:
    """``x tanh(softplus(x))`` (Misra 2019)."""
    return x * jnp.tanh(jax.nn.softplus(x))


def sinusoidal_embedding(t: jax.Array, dim: int) -> jax.Array:
    """Diffusion steps (B,) -> float32 (B, dim): ``[sin(t w_i), cos(t w_i)]`` with ``w_i = 10000^(-i / (dim/2 - 1))``,
    ``i = 0 .. dim/2 - 1`` (dim even, at least 4)."""
    half = dim // 2
    frequencies = jnp.exp(-jnp.log(10000.0) * jnp.arange(half, dtype=jnp.float32) / (half - 1))
    angles = t.astype(jnp.float32)[:, None] * frequencies
    return jnp.concatenate([jnp.sin(angles), jnp.cos(angles)], axis=-1)


class ConvBlock(nn.Module):
    """Conv1d (``kernel``, length kept) -> GroupNorm(``groups``) -> Mish over (B, L, C)."""

    features: int
    kernel: int
    groups: int

    @nn.compact
    def __call__(self, x):
        pad = self.kernel // 2
        x = Conv(self.features, (self.kernel,), padding=[(pad, pad)])(x)
        return mish(nn.GroupNorm(num_groups=self.groups, epsilon=GROUP_NORM_EPSILON)(x))


class ResidualBlock(nn.Module):
    """Two :class:`ConvBlock` s, FiLM-modulated in between by the condition (B, D): ``scale * h + bias`` per channel,
    both from ``Dense(mish(condition))``; a 1 x 1 convolution matches the residual's channels when they differ."""

    features: int
    kernel: int
    groups: int

    @nn.compact
    def __call__(self, x, condition):
        h = ConvBlock(self.features, self.kernel, self.groups)(x)
        scale, bias = jnp.split(nn.Dense(2 * self.features, name="film")(mish(condition)), 2, axis=-1)
        h = scale[:, None, :] * h + bias[:, None, :]
        h = ConvBlock(self.features, self.kernel, self.groups)(h)
        residual = x if x.shape[-1] == self.features else Conv(self.features, (1,), name="residual")(x)
        return h + residual


class TemporalUnet(nn.Module):
    """The noise-prediction network: ``(noisy actions (B, H, A), steps (B,), condition (B, D)) -> (B, H, A)``.

    Level ``i`` of the contracting path has two residual blocks of ``down_dims[i]`` channels and, but for the last,
    a stride-2 convolution (kernel 3) that halves the length; two more blocks follow at the bottom. The expanding
    path joins each level's output (but the first's) on the way back up: two blocks of ``down_dims[i - 1]``
    channels and a transposed convolution (kernel 4, stride 2) that doubles the length; a last ConvBlock and a
    1 x 1 convolution give the A outputs. ``H`` must be divisible by ``2^(len(down_dims) - 1)``. The diffusion
    step's sinusoidal embedding (``step_embedding`` wide) goes through Dense(4x), Mish, Dense and is joined to the
    condition that every block's FiLM reads.
    """

    action_dim: int
    down_dims: Sequence[int] = (256, 512, 1024)
    kernel: int = 5
    groups: int = 8
    step_embedding: int = 128

    @nn.compact
    def __call__(self, x, t, condition):
        embedding = sinusoidal_embedding(t, self.step_embedding)
        embedding = nn.Dense(self.step_embedding, name="step_out")(
            mish(nn.Dense(4 * self.step_embedding, name="step_in")(embedding)))
        condition = jnp.concatenate([embedding, condition.astype(jnp.float32)], axis=-1)
        block = dict(kernel=self.kernel, groups=self.groups)
        levels, skips = len(self.down_dims), []
        for i, width in enumerate(self.down_dims):
            x = ResidualBlock(width, **block, name=f"down{i}_a")(x, condition)
            x = ResidualBlock(width, **block, name=f"down{i}_b")(x, condition)
            skips.append(x)
            if i < levels - 1:
                x = Conv(width, (3,), strides=(2,), padding=[(1, 1)], name=f"down{i}_halve")(x)
        for j in range(2):
            x = ResidualBlock(self.down_dims[-1], **block, name=f"middle{j}")(x, condition)
        for i in range(levels - 1, 0, -1):
            width = self.down_dims[i - 1]
            x = jnp.concatenate([x, skips[i]], axis=-1)
            x = ResidualBlock(width, **block, name=f"up{i}_a")(x, condition)
            x = ResidualBlock(width, **block, name=f"up{i}_b")(x, condition)
            x = Conv(width, (4,), padding=[(2, 2)], dilation=2, name=f"up{i}_double")(x)  # length x 2
        x = ConvBlock(self.down_dims[0], self.kernel, self.groups, name="final_block")(x)
        return Conv(self.action_dim, (1,), name="final")(x)


# ---------------------------------------------------------------------------------------------- images
def crop(images: jax.Array, offsets: jax.Array, size: int) -> jax.Array:
    """``size`` x ``size`` windows of images (N, H, W, C) at top-left corners ``offsets`` int (N, 2) (row, column)."""
    def one(image, offset):
        return jax.lax.dynamic_slice(image, (offset[0], offset[1], 0), (size, size, image.shape[-1]))

    return jax.vmap(one)(images, offsets)


def random_offsets(key: jax.Array, count: int, height: int, width: int, size: int) -> jax.Array:
    """int32 (count, 2): top-left corners of ``size`` crops of (height, width) images, uniform over every position."""
    row_key, column_key = jax.random.split(key)
    return jnp.stack([jax.random.randint(row_key, (count,), 0, height - size + 1),
                      jax.random.randint(column_key, (count,), 0, width - size + 1)], axis=-1)


def center_offsets(count: int, height: int, width: int, size: int) -> jax.Array:
    """int32 (count, 2): the corner of the central ``size`` crop, repeated."""
    return jnp.broadcast_to(jnp.array([(height - size) // 2, (width - size) // 2], jnp.int32), (count, 2))


def _norm(width: int, group_size: int, name: str) -> nn.GroupNorm:
    return nn.GroupNorm(num_groups=max(1, width // group_size), epsilon=GROUP_NORM_EPSILON, name=name)


class BasicBlock(nn.Module):
    """ResNet's basic block: two 3 x 3 convolutions with GroupNorm and ReLU, a projected shortcut where the stride
    or the width changes."""

    width: int
    stride: int
    group_size: int

    @nn.compact
    def __call__(self, x):
        h = Conv(self.width, (3, 3), (self.stride, self.stride), padding=[(1, 1)] * 2, use_bias=False)(x)
        h = nn.relu(_norm(self.width, self.group_size, "norm1")(h))
        h = Conv(self.width, (3, 3), padding=[(1, 1)] * 2, use_bias=False)(h)
        h = _norm(self.width, self.group_size, "norm2")(h)
        if self.stride != 1 or x.shape[-1] != self.width:
            x = Conv(self.width, (1, 1), (self.stride, self.stride), use_bias=False, name="shortcut")(x)
            x = _norm(self.width, self.group_size, "shortcut_norm")(x)
        return nn.relu(h + x)


class ImageEncoder(nn.Module):
    """uint8 images (N, H, W, C) -> float32 (N, features).

    Pixels scaled to [-1, 1]; a ResNet stem (7 x 7 convolution of ``widths[0]`` channels at stride 2, GroupNorm,
    ReLU, 3 x 3 max-pool at stride 2), then stage ``i`` of ``blocks[i]`` basic blocks of ``widths[i]`` channels (the
    first at stride 2 from the second stage on). GroupNorm has ``width // group_size`` groups (at least one). A
    1 x 1 convolution makes ``keypoints`` maps whose spatial softmax gives each one's expected image point, and a
    Dense layer maps the 2 x ``keypoints`` coordinates to ``features``. Defaults: ResNet-18's torso (11.2M
    parameters), 32 keypoints, 64 features, as Diffusion Policy's robomimic encoder.
    """

    widths: Sequence[int] = (64, 128, 256, 512)
    blocks: Sequence[int] = (2, 2, 2, 2)
    group_size: int = 16
    keypoints: int = 32
    features: int = 64

    @nn.compact
    def __call__(self, images):
        x = images.astype(jnp.float32) * (2.0 / 255.0) - 1.0
        x = Conv(self.widths[0], (7, 7), (2, 2), padding=[(3, 3)] * 2, use_bias=False, name="stem")(x)
        x = nn.relu(_norm(self.widths[0], self.group_size, "stem_norm")(x))
        x = nn.max_pool(x, (3, 3), (2, 2), padding=[(1, 1)] * 2)
        for stage, (width, count) in enumerate(zip(self.widths, self.blocks, strict=True)):
            for b in range(count):
                stride = 2 if stage > 0 and b == 0 else 1
                x = BasicBlock(width, stride, self.group_size, name=f"stage{stage}_block{b}")(x)
        maps = Conv(self.keypoints, (1, 1), name="keypoint_maps")(x)
        points = spatial_softmax(maps).reshape(maps.shape[0], -1)  # (N, 2 keypoints), each in [-1, 1]
        return nn.Dense(self.features, name="out")(points)


class ObservationEncoder(nn.Module):
    """``{"vector": float32 (N, D), "images": {key: uint8 (N, h, w, C)}}`` (images already cropped) -> float32
    (N, D + len(images) * features): one :class:`ImageEncoder` per image key (sorted), then the vector."""

    widths: Sequence[int] = ImageEncoder.widths
    blocks: Sequence[int] = ImageEncoder.blocks
    group_size: int = ImageEncoder.group_size
    keypoints: int = ImageEncoder.keypoints
    features: int = ImageEncoder.features

    @nn.compact
    def __call__(self, observation):
        parts = [ImageEncoder(tuple(self.widths), tuple(self.blocks), self.group_size, self.keypoints, self.features,
                              name=f"{key}_encoder")(observation["images"][key])
                 for key in sorted(observation["images"])]
        return jnp.concatenate(parts + [observation["vector"].astype(jnp.float32)], axis=-1)
