"""SAC kernels checked against hand-worked values and plain-numpy references."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena_agents.sac.losses import (
    actor_loss,
    critic_loss,
    polyak_update,
    sample_squashed_gaussian,
    squashed_gaussian_log_prob,
    tanh_log_det,
    temperature_loss,
)


def squashed_log_prob_reference(u, mean, log_std):
    """log N(u; mean, std) - sum log(1 - tanh(u)^2), in float64 numpy."""
    u, mean, log_std = (np.asarray(x, np.float64) for x in (u, mean, log_std))
    std = np.exp(log_std)
    gaussian = -0.5 * ((u - mean) / std) ** 2 - np.log(std) - 0.5 * np.log(2 * np.pi)
    return np.sum(gaussian - np.log(1 - np.tanh(u) ** 2), axis=-1)


def test_tanh_log_det_hand_worked_and_stable():
    # u = 0: tanh' = 1 -> log 1 = 0;  u = atanh(0.6): 1 - 0.36 = 0.64;  two dims add up.
    u = jnp.array([[0.0, 0.0], [np.arctanh(0.6), 0.0], [np.arctanh(0.6), np.arctanh(0.6)]], jnp.float32)
    np.testing.assert_allclose(tanh_log_det(u), [0.0, np.log(0.64), 2 * np.log(0.64)], rtol=1e-5, atol=1e-6)
    # Far in the tails tanh(u)^2 rounds to 1 in float32 (the naive form gives -inf); 2 (log 2 - |u|) is exact.
    far = jnp.array([[20.0], [-20.0]], jnp.float32)
    np.testing.assert_allclose(tanh_log_det(far), [2 * (np.log(2) - 20)] * 2, rtol=1e-6)


def test_squashed_gaussian_log_prob_hand_worked_and_reference():
    # Standard normal at u = 0: tanh' = 1, so log pi = -log(2 pi) / 2 = -0.9189385.
    assert float(squashed_gaussian_log_prob(jnp.zeros((1, 1)), jnp.zeros((1, 1)), jnp.zeros((1, 1)))[0]) == \
        pytest.approx(-0.9189385, abs=1e-6)
    # u = atanh(0.6) = log 2, mean 0.5, std e^-1: z = (0.6931472 - 0.5) / 0.3678794 = 0.5250285;
    # log N = -z^2/2 + 1 - 0.9189385 = -0.0567660; minus log(0.64) = -0.4462871 -> 0.3895211.
    u = jnp.array([[np.arctanh(0.6)]], jnp.float32)
    value = squashed_gaussian_log_prob(u, jnp.array([[0.5]]), jnp.array([[-1.0]]))
    assert float(value[0]) == pytest.approx(0.3895211, abs=1e-5)
    rng = np.random.default_rng(0)
    u, mean, log_std = rng.normal(size=(3, 5, 3)) * [[[2.0]], [[1.0]], [[0.5]]]
    np.testing.assert_allclose(squashed_gaussian_log_prob(jnp.asarray(u, jnp.float32), jnp.asarray(mean, jnp.float32),
                                                          jnp.asarray(log_std, jnp.float32)),
                               squashed_log_prob_reference(u, mean, log_std), rtol=1e-5, atol=1e-5)


def test_squashed_gaussian_density_integrates_to_one_over_the_bounds():
    a = np.linspace(-1 + 1e-6, 1 - 1e-6, 400_001)
    u = jnp.asarray(np.arctanh(a)[:, None], jnp.float32)
    for mean, log_std in [(0.0, 0.0), (1.5, -0.5), (-0.3, 0.7)]:
        logp = squashed_gaussian_log_prob(u, jnp.full_like(u, mean), jnp.full_like(u, log_std))
        assert np.trapezoid(np.exp(np.asarray(logp, np.float64)), a) == pytest.approx(1.0, abs=2e-3)


def test_sample_squashed_gaussian_is_reparameterised():
    mean = jnp.array([[0.3, -1.0]] * 4096, jnp.float32)
    log_std = jnp.full_like(mean, -1.0)
    action, logp = sample_squashed_gaussian(jax.random.key(0), mean, log_std)
    assert action.shape == (4096, 2) and logp.shape == (4096,)
    assert bool(jnp.all(jnp.abs(action) < 1.0))
    # its log density is that of the pre-tanh Gaussian sample it came from
    pre = mean + jnp.exp(log_std) * jax.random.normal(jax.random.key(0), mean.shape)
    np.testing.assert_allclose(action, jnp.tanh(pre), rtol=1e-6)
    np.testing.assert_allclose(logp, squashed_log_prob_reference(pre, mean, log_std), rtol=1e-4, atol=1e-4)
    # d tanh(mean + std eps) / d mean = 1 - tanh^2: gradients flow through the sample
    grad = jax.grad(lambda m: jnp.sum(sample_squashed_gaussian(jax.random.key(0), m, log_std)[0]))(mean)
    np.testing.assert_allclose(grad, 1 - action**2, rtol=1e-5, atol=1e-6)


def test_critic_loss_hand_worked():
    # alpha = 0.2, discount = 0.9.
    # min(Q1', Q2') = [2, 4];  soft value = [2 - 0.2 * 0.5, 4 + 0.2 * 1] = [1.9, 4.2]
    # y = [1 + 0.9 * 1.9, 0 + 0 (terminated)] = [2.71, 0]
    # Q1 - y = [-1.71, 2] -> mean sq 3.46205;  Q2 - y = [-1.21, 1] -> mean sq 1.23205;  loss = 2.34705
    q1, q2 = jnp.array([1.0, 2.0]), jnp.array([1.5, 1.0])
    args = (jnp.array([3.0, 4.0]), jnp.array([2.0, 5.0]), jnp.array([0.5, -1.0]), jnp.array([1.0, 0.0]),
            jnp.array([False, True]), jnp.asarray(0.2), 0.9)
    loss, terms = critic_loss(q1, q2, *args)
    assert float(loss) == pytest.approx(2.34705, abs=1e-5)
    assert float(terms.target) == pytest.approx(1.355, abs=1e-6)
    assert float(terms.q1) == pytest.approx(1.5) and float(terms.q2) == pytest.approx(1.25)
    # d loss / d Q = (Q - y) / N for each critic; the target carries no gradient
    g1, g2, gt1, gt2, glogp = jax.grad(lambda *x: critic_loss(*x, *args[3:])[0], argnums=(0, 1, 2, 3, 4))(
        q1, q2, *args[:3])
    np.testing.assert_allclose(g1, [-0.855, 1.0], rtol=1e-5)
    np.testing.assert_allclose(g2, [-0.605, 0.5], rtol=1e-5)
    for g in (gt1, gt2, glogp):
        np.testing.assert_array_equal(g, 0.0)


def test_critic_loss_bootstraps_unless_terminated():
    # A step that was only truncated is passed with terminated = False: it bootstraps like any other.
    ones = jnp.ones((1,))
    go_on, _ = critic_loss(ones * 0, ones * 0, ones * 10, ones * 10, ones * 0, ones, jnp.array([False]), 1.0, 0.5)
    stop, _ = critic_loss(ones * 0, ones * 0, ones * 10, ones * 10, ones * 0, ones, jnp.array([True]), 1.0, 0.5)
    assert float(go_on) == pytest.approx(36.0)  # y = 1 + 0.5 * 10 = 6
    assert float(stop) == pytest.approx(1.0)  # y = 1


def test_actor_loss_hand_worked():
    # alpha * logp - min(Q1, Q2) = [0.1 - 1, -0.2 - 2] = [-0.9, -2.2] -> mean -1.55
    logp, q1, q2 = jnp.array([0.5, -1.0]), jnp.array([1.0, 3.0]), jnp.array([2.0, 2.0])
    assert float(actor_loss(logp, q1, q2, jnp.asarray(0.2))) == pytest.approx(-1.55)
    g_logp, g_q1, g_q2, g_alpha = jax.grad(actor_loss, argnums=(0, 1, 2, 3))(logp, q1, q2, jnp.asarray(0.2))
    np.testing.assert_allclose(g_logp, [0.1, 0.1])
    np.testing.assert_allclose(g_q1, [-0.5, 0.0])  # the smaller critic takes the gradient
    np.testing.assert_allclose(g_q2, [0.0, -0.5])
    assert float(g_alpha) == 0.0


def test_temperature_loss_hand_worked():
    # log_alpha = log 0.5; logp + target = [0.5 - 1, -1 - 1] -> mean -1.25; loss = 1.25 log 0.5 = -0.8664340
    logp = jnp.array([0.5, -1.0])
    log_alpha = jnp.log(0.5)
    assert float(temperature_loss(log_alpha, logp, -1.0)) == pytest.approx(-0.866434, abs=1e-6)
    g_alpha, g_logp = jax.grad(temperature_loss, argnums=(0, 1))(log_alpha, logp, -1.0)
    # gradient = entropy - target = 0.25 - (-1) > 0: entropy above target, so descent lowers alpha
    assert float(g_alpha) == pytest.approx(1.25)
    np.testing.assert_array_equal(g_logp, 0.0)
    assert float(jax.grad(temperature_loss)(log_alpha, logp, 2.0)) == pytest.approx(-1.75)  # below: raise alpha


def test_polyak_update_hand_worked():
    target = {"w": jnp.array([0.0, 10.0]), "b": jnp.array(4.0)}
    online = {"w": jnp.array([1.0, 20.0]), "b": jnp.array(-6.0)}
    new = polyak_update(target, online, 0.1)
    np.testing.assert_allclose(new["w"], [0.1, 11.0], rtol=1e-6)
    assert float(new["b"]) == pytest.approx(3.0)
    jax.tree_util.tree_map(np.testing.assert_array_equal, polyak_update(target, online, 1.0), online)
