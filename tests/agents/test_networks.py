import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena.core.spec import Box
from jarena_agents import networks


def test_actor_critic_value_mlp_has_its_own_layers():
    net = networks.ActorCritic(Box(-1.0, 1.0, (2,)), hidden=(8,), value_hidden=(16, 16))
    params = net.init(jax.random.key(0), jnp.zeros((3, 5)))["params"]
    assert [params["actor"][f"Dense_{i}"]["kernel"].shape for i in range(2)] == [(5, 8), (8, 2)]
    assert [params["critic"][f"Dense_{i}"]["kernel"].shape for i in range(3)] == [(5, 16), (16, 16), (16, 1)]
    policy, value = net.apply({"params": params}, jnp.zeros((3, 5)))
    assert policy.mean.shape == policy.log_std.shape == (3, 2) and value.shape == (3,)
    shared = networks.ActorCritic(Box(-1.0, 1.0, (2,)), hidden=(8,)).init(jax.random.key(0), jnp.zeros((3, 5)))
    assert shared["params"]["critic"]["Dense_0"]["kernel"].shape == (5, 8)  # default: the policy's layers


def test_tanh_normal_log_prob_is_the_change_of_variables():
    """log p(a) for a = tanh(u), u ~ N(mean, std): log N(u) - sum log(1 - tanh(u)^2), checked against a
    direct density: the Gaussian's pdf times |du/da| = 1 / (1 - a^2), per dimension."""
    from scipy.stats import norm

    mean, std = jnp.array([0.3, -1.2]), jnp.array([0.5, 0.8])
    u = jnp.array([1.1, -0.4])
    policy = networks.TanhNormal(mean, std)
    a = np.tanh(np.asarray(u, np.float64))
    expected = np.sum(norm.logpdf(np.asarray(u), np.asarray(mean), np.asarray(std)) - np.log(1 - a**2))
    np.testing.assert_allclose(policy.log_prob(u), expected, rtol=1e-5)
    # stable far into saturation, where 1 - tanh(u)^2 underflows in float32
    assert np.isfinite(policy.log_prob(jnp.array([30.0, -30.0])))
    np.testing.assert_allclose(networks._log_tanh_derivative(jnp.array(30.0)), 2 * (np.log(2) - 30), rtol=1e-6)
    np.testing.assert_allclose(policy.unit(u), a, rtol=1e-6)
    entropy = policy.entropy()  # Gaussian entropy + log-determinant at the mode
    np.testing.assert_allclose(entropy, np.sum(norm.entropy(np.asarray(mean), np.asarray(std))
                                               + np.log(1 - np.tanh(np.asarray(mean, np.float64)) ** 2)), rtol=1e-5)


def test_tanh_normal_head_acts_inside_the_bounds():
    spec = Box(np.array([-2.0, 0.0]), np.array([2.0, 1.0]), (2,))
    net = networks.ActorCritic(spec, hidden=(8,), box_policy="tanh_normal")
    params = net.init(jax.random.key(0), jnp.zeros((64, 3)))
    policy, _ = net.apply(params, 3 * jax.random.normal(jax.random.key(1), (64, 3)))
    assert isinstance(policy, networks.TanhNormal) and bool(jnp.all(policy.std >= 1e-3))
    raw, logp, _ = networks.sample_action(spec, policy, jax.random.key(2), False)
    action = networks.to_env_action(spec, raw, policy)
    assert bool(jnp.all((action > spec.low) & (action < spec.high)))
    np.testing.assert_allclose(logp, policy.log_prob(raw))
    mode, _, _ = networks.sample_action(spec, policy, None, True)
    np.testing.assert_allclose(networks.to_env_action(spec, mode, policy)[:, 0], 2 * np.tanh(policy.mean[:, 0]),
                               rtol=1e-5, atol=1e-6)


def test_mlp_activation_is_configurable():
    x = jnp.linspace(-3, 3, 10)[:, None]
    outputs = {}
    for name in networks.ACTIVATIONS:
        mlp = networks.MLP((4,), 1, activation=name)
        params = mlp.init(jax.random.key(0), x)  # same key: same weights, only the activation differs
        hidden, out = params["params"]["Dense_0"], params["params"]["Dense_1"]
        expected = networks.ACTIVATIONS[name](x @ hidden["kernel"] + hidden["bias"]) @ out["kernel"] + out["bias"]
        outputs[name] = mlp.apply(params, x)
        np.testing.assert_allclose(outputs[name], expected, rtol=1e-5, atol=1e-6)
    assert not np.allclose(outputs["tanh"], outputs["swish"])
    with pytest.raises(ValueError, match="unknown activation 'gelu'; choose from tanh, relu, swish"):
        networks.MLP((4,), 1, activation="gelu").init(jax.random.key(0), x)


def test_spatial_softmax_gives_each_channel_its_expected_image_point():
    from jarena_agents.networks import PixelEncoder, spatial_softmax

    maps = np.full((1, 8, 8, 3), -50.0, np.float32)
    maps[0, 1, 6, 0] = 50.0  # channel 0 peaks at row 1, column 6
    maps[0, 4, 2, 1] = 50.0  # channel 1 at row 4, column 2
    out = np.asarray(spatial_softmax(jnp.asarray(maps)))  # (N, C, 2): (u, v) per channel
    np.testing.assert_allclose(out[0, 0], [6.5 / 4 - 1, 1.5 / 4 - 1], atol=1e-6)
    np.testing.assert_allclose(out[0, 1], [2.5 / 4 - 1, 4.5 / 4 - 1], atol=1e-6)
    np.testing.assert_allclose(out[0, 2], [0.0, 0.0], atol=1e-6)  # a flat map: the image's centre
    encoder = PixelEncoder(((4, 3, 2),), "SAME", "spatial_softmax")
    images = {"rgb": jnp.zeros((2, 5, 16, 16, 3), jnp.uint8)}
    features = encoder.apply(encoder.init(jax.random.key(0), images), images)
    assert features.shape == (2, 5, 8)  # 4 channels x (u, v)
