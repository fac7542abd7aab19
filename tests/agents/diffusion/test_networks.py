"""Diffusion Policy's networks: the image encoders, the crops and the default sizes."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena_agents.diffusion import networks


def count(params) -> int:
    return sum(int(np.prod(x.shape)) for x in jax.tree_util.tree_leaves(params))


def test_one_groupnorm_encoder_per_image_key_joined_with_the_vector():
    # small widths and images: the behaviour checked (separate encoders, per-sample normalisation) is size-free
    encoder = networks.ObservationEncoder(widths=(4, 8), blocks=(1, 1), group_size=4, keypoints=3, features=5)
    images = np.random.default_rng(0).integers(0, 256, (2, 3, 12, 12, 3), np.uint8)
    observation = {"vector": np.arange(6.0, dtype=np.float32).reshape(3, 2),
                   "images": {"wrist": images[0], "top": images[1]}}
    params = jax.jit(lambda key: networks.init_params(encoder, key, observation))(jax.random.key(1))
    assert set(params["params"]) == {"top_encoder", "wrist_encoder"} and "batch_stats" not in params

    changed = dict(observation, images={k: np.concatenate([v[:1], 255 - v[1:]])
                                        for k, v in observation["images"].items()})
    both = jax.tree_util.tree_map(lambda *x: np.stack(x), observation, changed)
    out, changed = jax.jit(jax.vmap(encoder.apply, in_axes=(None, 0)))(params, both)  # one program for both
    assert out.shape == (3, 5 + 5 + 2)
    np.testing.assert_array_equal(out[:, -2:], observation["vector"])  # the vector joins the image features as it is
    # GroupNorm normalises each image alone: the first sample's features do not move when the others change
    np.testing.assert_allclose(changed[0], out[0], rtol=1e-6)
    assert not np.allclose(changed[1:, :10], out[1:, :10])
    # the keys' features differ: "top" (sorted first) and "wrist" have encoders of their own
    assert not np.allclose(out[:, :5], out[:, 5:10])


def test_convolutions_as_matrix_products_match_xla_convolutions():
    """The ResNet stem's 7 x 7 stride-2 convolution and the U-Net's length-doubling one (input dilated by 2): the
    matrix product over unfolded windows (what ``Conv`` runs on the CPU) and XLA's operator through ``convolve``
    (what it runs on a GPU) both equal XLA's convolution called directly."""
    cases = [((2, 9, 11, 3), (7, 7), (2, 2), [(3, 3)] * 2, 1, ("NHWC", "HWIO", "NHWC")),
             ((2, 4, 5), (4,), (1,), [(2, 2)], 2, ("NWC", "WIO", "NWC"))]

    rng = np.random.default_rng(0)
    inputs = [(rng.normal(size=shape).astype(np.float32), rng.normal(size=size + (shape[-1], 6)).astype(np.float32))
              for shape, size, *_ in cases]

    @jax.jit
    def compare(inputs):
        out = []
        for (x, kernel), (_, size, strides, padding, dilation, numbers) in zip(inputs, cases, strict=True):
            conv = networks.Conv(6, size, strides, padding, use_bias=False, dilation=dilation)
            xla = jax.lax.conv_general_dilated(x, kernel, strides, padding, lhs_dilation=(dilation,) * len(size),
                                               dimension_numbers=numbers)
            out.append((conv.apply({"params": {"kernel": kernel}}, x), xla,
                        networks.convolve(x, kernel, strides, padding, dilation, method="matmul"),
                        networks.convolve(x, kernel, strides, padding, dilation, method="xla")))
        return out

    for ours, xla, matmul, operator in compare(inputs):
        assert ours.shape == xla.shape == matmul.shape == operator.shape
        for got in (ours, matmul, operator):
            np.testing.assert_allclose(got, xla, atol=1e-5)
    with pytest.raises(ValueError, match="valid: auto, matmul, xla"):
        networks.convolve(*inputs[0], (2, 2), [(3, 3)] * 2, method="cudnn")


def test_crops():
    images = np.arange(2 * 6 * 6).reshape(2, 6, 6, 1)

    @jax.jit
    def crops():
        return (networks.center_offsets(2, 96, 96, 84), networks.crop(images, jnp.array([[0, 1], [2, 0]]), 4),
                networks.random_offsets(jax.random.key(0), 4000, 96, 90, 84))

    center, cropped, offsets = crops()
    np.testing.assert_array_equal(center, [[6, 6], [6, 6]])
    np.testing.assert_array_equal(cropped[0, ..., 0], images[0, 0:4, 1:5, 0])
    np.testing.assert_array_equal(cropped[1, ..., 0], images[1, 2:6, 0:4, 0])
    offsets = np.asarray(offsets)
    assert offsets[:, 0].min() == 0 and offsets[:, 0].max() == 12 and offsets[:, 1].max() == 6  # every corner


def test_default_sizes():
    """ResNet-18's torso as the image encoder; the U-Net at Diffusion Policy's real-robot size for a PushT-like
    condition (2 steps of 64 image features and a 2-d position), traced, not run."""
    encoder = networks.ImageEncoder()
    shapes = jax.eval_shape(encoder.init, jax.random.key(0), jnp.zeros((1, 84, 84, 3), jnp.uint8))
    assert 11.1e6 < count(shapes) < 11.3e6

    def unet_size(down_dims):
        unet = networks.TemporalUnet(2, down_dims)
        return count(jax.eval_shape(unet.init, jax.random.key(0), jnp.zeros((1, 16, 2)), jnp.zeros((1,), jnp.int32),
                                    jnp.zeros((1, 2 * 66))))

    # the paper's real-robot rows: 67M with their conditions (its simulation rows' [512, 1024, 2048]: 252M here)
    assert 64e6 < unet_size((256, 512, 1024)) < 66e6
