"""Transporter's networks: the transport's cross-correlation against a hand computation, and the fully convolutional
ResNet's shapes."""

import jax
import jax.numpy as jnp
import numpy as np

from jarena_agents.networks import init_params
from jarena_agents.transporter import networks


def test_the_correlation_is_the_hand_computed_sum_and_finds_a_placed_pattern():
    """A feature pattern (3 x 3 x 2) placed in an empty scene at rows 5-7, columns 2-4 is found there: the kernel
    that is the pattern scores highest at the offset (5, 2), the kernel of another pattern does not."""
    rng = np.random.default_rng(0)
    pattern = rng.normal(size=(3, 3, 2)).astype(np.float32)
    other = rng.normal(size=(3, 3, 2)).astype(np.float32)
    scene = np.zeros((12, 10, 2), np.float32)
    scene[5:8, 2:5] = pattern
    scene += 0.01 * rng.normal(size=scene.shape).astype(np.float32)
    out = np.asarray(jax.jit(networks.correlate)(scene, np.stack([pattern, other])))
    assert out.shape == (10, 8, 2)
    hand = np.zeros((10, 8, 2), np.float32)
    for r in range(10):
        for c in range(8):
            for k, kernel in enumerate((pattern, other)):
                hand[r, c, k] = np.sum(scene[r:r + 3, c:c + 3] * kernel)
    np.testing.assert_allclose(out, hand, rtol=1e-5, atol=1e-5)
    assert np.unravel_index(np.argmax(out[..., 0]), (10, 8)) == (5, 2)
    assert out[5, 2, 0] > out[5, 2, 1]


def test_the_correlation_and_its_gradients_equal_the_direct_convolution_on_ravens_kernel_size():
    """The FFT correlation against ``lax.conv`` at Ravens' odd 65 x 65 kernels (a crop of 64 padded by one) over a
    non-square scene: the same values and the same gradients for both inputs, to float32 rounding."""
    key = jax.random.key(3)
    scene = jax.random.normal(key, (100, 84, 3))
    kernels = jax.random.normal(jax.random.fold_in(key, 1), (4, 65, 65, 3))

    def direct(s, k):
        return jax.lax.conv_general_dilated(s[None], jnp.transpose(k, (1, 2, 3, 0)), (1, 1), "VALID",
                                            dimension_numbers=("NHWC", "HWIO", "NHWC"),
                                            precision=jax.lax.Precision.HIGHEST)[0]

    weights = jax.random.normal(jax.random.fold_in(key, 2), (36, 20, 4))
    ours, theirs = networks.correlate(scene, kernels), direct(scene, kernels)
    assert ours.shape == theirs.shape == (36, 20, 4)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=2e-5 * float(jnp.max(jnp.abs(theirs))))
    for a, b in zip(jax.grad(lambda s, k: jnp.sum(weights * networks.correlate(s, k)), argnums=(0, 1))(scene, kernels),
                    jax.grad(lambda s, k: jnp.sum(weights * direct(s, k)), argnums=(0, 1))(scene, kernels),
                    strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=2e-5 * float(jnp.max(jnp.abs(b))))


class Channels:
    """A stand-in for an FCN: the raw (unstandardised) input channels ``take``."""

    stride = 1

    def __init__(self, take):
        self.take = take

    def apply(self, params, x):
        mean = jnp.asarray([networks.COLOR_MEAN] * 3 + [networks.HEIGHT_MEAN] * 3)
        std = jnp.asarray([networks.COLOR_STD] * 3 + [networks.HEIGHT_STD] * 3)
        return (x * std + mean)[..., self.take]


def test_the_transport_scores_the_pick_window_where_it_reappears_with_its_turn():
    """Query features: the object's channels (0-2) around the pick; key features: the target's channels (3-5). The
    target is the object's pattern turned by +90 degrees of yaw (``np.rot90(-1)``) about another point: the place
    logits peak there, at the quarter turn's yaw bin."""
    image = np.zeros((24, 20, 6), np.float32)
    blob = np.random.default_rng(1).uniform(0.5, 1.0, (3, 4, 3)).astype(np.float32)
    image[4:7, 3:7, :3] = blob  # the object, its pick at (5, 4)
    image[14:18, 12:15, 3:] = np.rot90(blob, -1)  # the target: the pick point goes to (15, 13)
    yaws = jnp.array([0.0, np.pi / 2, np.pi, -np.pi / 2])
    logits = np.asarray(jax.jit(lambda image, pick: networks.transport_logits(
        Channels(slice(3, 6)), Channels(slice(0, 3)), None, None, image, pick, yaws, 8))(image, np.array([5, 4])))
    assert logits.shape == (24, 20, 4)
    assert np.unravel_index(np.argmax(logits), logits.shape) == (15, 13, 1)
    np.testing.assert_allclose(logits[15, 13, 1], np.sum(blob ** 2), rtol=1e-4)


def test_the_fcn_keeps_the_image_size_at_any_size():
    net = networks.FCN(widths=(4, 4), head=4, features=3)  # stride 2: padded, downsampled, upsampled, cut back
    out = jax.jit(lambda key, x: networks.apply_fcn(net, init_params(net, key, x[:, :4, :4]), x))(
        jax.random.key(0), jnp.ones((2, 13, 10, 6)))
    assert out.shape == (2, 13, 10, 3) and bool(jnp.all(jnp.isfinite(out)))
