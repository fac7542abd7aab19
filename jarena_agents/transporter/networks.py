"""Transporter's networks (Zeng et al. 2020): a fully convolutional ResNet, the attention (pick) logits and the
transport (place) logits by cross-correlation, channels last.

Inputs are Ravens' 6 channels per pixel: the colour (3 channels, scaled to [0, 1]) and the height replicated to 3
channels, each standardised with Ravens' dataset statistics (:func:`normalize`). Images are padded with zeros
(black, at the table's height) before they are standardised, as Ravens pads them.

- attention: the image padded to a square goes through an :class:`FCN` of one output channel; its logits over the
  image's pixels (the padding cut away) score the pick point.
- transport: the image padded by ``crop / 2`` on every side goes through the key FCN; the ``crop`` x ``crop``
  window around the pick, turned to each of R yaws (:func:`jarena_agents.transporter.se2.rotated_crops`), goes
  through the query FCN; the place logits (H, W, R) are the cross-correlation of the scene's features with each
  crop's (:func:`correlate`): the score of putting the pick point at pixel ``(r, c)`` with the object turned by yaw
  ``k``.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

from jarena_agents.transporter import se2

COLOR_MEAN, COLOR_STD = 0.18877631, 0.07276466
"""Ravens' colour statistics (channels scaled to [0, 1])."""
HEIGHT_MEAN, HEIGHT_STD = 0.00509261, 0.00903967
"""Ravens' height statistics, metres."""
CHANNELS = 6


def raw_input(rgb: jax.Array, height: jax.Array) -> jax.Array:
    """float32 (..., H, W, 6): colour uint8 (..., H, W, 3) scaled to [0, 1] and height (..., H, W) metres, three
    times. Zeros are the padding value (:func:`normalize` comes after padding and cropping)."""
    colour = rgb.astype(jnp.float32) / 255.0
    height = jnp.broadcast_to(height.astype(jnp.float32)[..., None], height.shape + (3,))
    return jnp.concatenate([colour, height], axis=-1)


def normalize(raw: jax.Array) -> jax.Array:
    """:func:`raw_input`'s channels standardised: (x - mean) / std, Ravens' statistics for colour and height."""
    mean = jnp.asarray([COLOR_MEAN] * 3 + [HEIGHT_MEAN] * 3, jnp.float32)
    std = jnp.asarray([COLOR_STD] * 3 + [HEIGHT_STD] * 3, jnp.float32)
    return (raw - mean) / std


class Block(nn.Module):
    """Ravens' residual block: 1x1, 3x3 and 1x1 convolutions of ``widths`` (ReLU between them), added to the input
    (through a strided 1x1 convolution where ``project``), then a ReLU unless ``last``."""

    widths: tuple[int, int, int]
    strides: int = 1
    project: bool = False
    last: bool = False

    @nn.compact
    def __call__(self, x):
        first, middle, out = self.widths
        stride = (self.strides, self.strides)
        y = nn.relu(nn.Conv(first, (1, 1), stride)(x))
        y = nn.relu(nn.Conv(middle, (3, 3), padding="SAME")(y))
        y = nn.Conv(out, (1, 1))(y)
        shortcut = nn.Conv(out, (1, 1), stride)(x) if self.project else x
        y = y + shortcut
        return y if self.last else nn.relu(y)


class FCN(nn.Module):
    """A fully convolutional ResNet, Ravens' ``ResNet43_8s`` with its default ``widths``: (N, H, W, C) ->
    (N, H, W, ``features``), H and W multiples of :attr:`stride`.

    A 3x3 stem of ``widths[0]``; one stage per width (a projecting block, strided by 2 from the second stage on,
    then an identity block); one stage per width of ``reversed(widths[:-1])``, each followed by a bilinear 2x
    upsampling; a head stage of ``(head, head, features)`` without the final ReLUs.
    """

    widths: tuple[int, ...] = (64, 128, 256, 512)
    head: int = 16
    features: int = 1

    @property
    def stride(self) -> int:
        return 2 ** (len(self.widths) - 1)

    @nn.compact
    def __call__(self, x):
        x = nn.relu(nn.Conv(self.widths[0], (3, 3), padding="SAME")(x))
        for i, width in enumerate(self.widths):
            x = Block((width,) * 3, strides=1 if i == 0 else 2, project=True)(x)
            x = Block((width,) * 3)(x)
        for width in reversed(self.widths[:-1]):
            x = Block((width,) * 3, project=True)(x)
            x = Block((width,) * 3)(x)
            n, h, w, c = x.shape
            x = jax.image.resize(x, (n, 2 * h, 2 * w, c), "bilinear")
        widths = (self.head, self.head, self.features)
        x = Block(widths, project=True, last=True)(x)
        return Block(widths, last=True)(x)


def apply_fcn(net: FCN, params, x: jax.Array) -> jax.Array:
    """``net`` on float32 (N, H, W, C) of any H and W: padded with zeros at the far ends to multiples of its stride,
    and its output (N, H, W, features) cut back."""
    height, width = x.shape[1:3]
    pad = [(-height) % net.stride, (-width) % net.stride]
    out = net.apply(params, jnp.pad(x, ((0, 0), (0, pad[0]), (0, pad[1]), (0, 0))))
    return out[:, :height, :width]


def correlate(scene: jax.Array, kernels: jax.Array) -> jax.Array:
    """Cross-correlation of ``scene`` features (Hs, Ws, F) with R kernels (R, k, k, F): (Hs - k + 1, Ws - k + 1, R),
    ``out[r, c, i] = sum over (u, v, f) of scene[r + u, c + v, f] kernels[i, u, v, f]``, in float32.

    Computed through 2-D FFTs of size (Hs, Ws): the product of the scene's spectrum and each flipped kernel's is
    their circular convolution, which equals the linear one on the (Hs - k + 1, Ws - k + 1) outputs kept. Ravens'
    36 kernels of 65 x 65 x 3 over a 384 x 224 scene are 47 GFLOP as a direct convolution, forward only; through
    FFTs the same values (to float32 rounding) come 23x faster forward and backward, an update of the paper's
    networks 1.83x (2 CPU cores, ``benchmarks/transporter_update.py``; ``tests/agents/transporter/test_networks.py``
    checks it against the direct sum and its gradients)."""
    height, width = scene.shape[:2]
    rows, cols = kernels.shape[1:3]
    spectrum = jnp.fft.rfft2(jnp.transpose(scene.astype(jnp.float32), (2, 0, 1)))  # (F, Hs, Ws // 2 + 1)
    flipped = jnp.transpose(kernels.astype(jnp.float32)[:, ::-1, ::-1], (0, 3, 1, 2))  # (R, F, k, k)
    product = jnp.einsum("fhw,rfhw->rhw", spectrum, jnp.fft.rfft2(flipped, s=(height, width)))
    out = jnp.fft.irfft2(product, s=(height, width))[:, rows - 1:, cols - 1:]  # (R, H, W)
    return jnp.transpose(out, (1, 2, 0))


def attention_logits(net: FCN, params, raw: jax.Array) -> jax.Array:
    """Pick logits (H, W) of one image's :func:`raw_input` (H, W, 6), padded to a square for the network."""
    height, width = raw.shape[:2]
    side = max(height, width)
    top, left = (side - height) // 2, (side - width) // 2
    padded = jnp.pad(raw, ((top, side - height - top), (left, side - width - left), (0, 0)))
    logits = apply_fcn(net, params, normalize(padded)[None])[0, :, :, 0]
    return logits[top:top + height, left:left + width]


def transport_logits(key_net: FCN, query_net: FCN, key_params, query_params, raw: jax.Array, pick: jax.Array,
                     yaws: jax.Array, crop: int) -> jax.Array:
    """Place logits (H, W, R) of one image's :func:`raw_input` (H, W, 6) for the pick pixel ``pick`` (2,) and the
    object turned by each of ``yaws`` (R,) radians; ``crop`` even.

    The key features of the image padded by ``crop / 2`` (H + crop, W + crop, F) are correlated with the query
    features of the R turned crops (R, crop, crop, F), each padded by a row and a column of zeros at its far end so
    that its centre, the pick point, is the middle of an odd kernel: logit ``(r, c, k)`` compares the scene around
    ``(r, c)`` with the pick's surroundings turned by ``yaws[k]``.
    """
    half = crop // 2
    scene = jnp.pad(raw, ((half, half), (half, half), (0, 0)))
    scene = apply_fcn(key_net, key_params, normalize(scene)[None])[0]
    crops = normalize(se2.rotated_crops(raw, pick, yaws, crop))
    kernels = jnp.pad(apply_fcn(query_net, query_params, crops), ((0, 0), (0, 1), (0, 1), (0, 0)))
    return correlate(scene, kernels)
