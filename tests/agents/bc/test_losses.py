import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena_agents.bc.losses import cross_entropy, gaussian_nll, mixture_nll, mse

HALF_LOG_2PI = 0.5 * np.log(2 * np.pi)  # 0.918939


def test_mse_sums_action_dimensions_and_averages_samples():
    prediction = jnp.array([[1.0, 2.0], [0.0, 0.0]])
    target = jnp.array([[0.0, 0.0], [1.0, 1.0]])
    assert float(mse(prediction, target)) == pytest.approx((5.0 + 2.0) / 2)  # (1 + 4), (1 + 1)


def test_mse_averages_over_a_chunk_axis_too():
    prediction = jnp.zeros((2, 3, 1))  # (batch, K, d)
    target = jnp.arange(6.0).reshape(2, 3, 1)
    assert float(mse(prediction, target)) == pytest.approx(sum(i * i for i in range(6)) / 6)


def test_gaussian_nll_by_hand():
    mean = jnp.array([[0.0], [0.0]])
    log_std = jnp.array([[0.0], [np.log(2.0)]])
    target = jnp.array([[1.0], [2.0]])
    # sample 1: z = 1, std 1 -> 0.5 + 0 + 0.9189; sample 2: z = 2 / 2 = 1, std 2 -> 0.5 + log 2 + 0.9189
    first, second = 0.5 + HALF_LOG_2PI, 0.5 + np.log(2.0) + HALF_LOG_2PI
    assert float(gaussian_nll(mean, log_std, target)) == pytest.approx((first + second) / 2, rel=1e-6)
    # beta = 0.5 weights each sample by std^(2 * 0.5) = std: 1 and 2
    assert float(gaussian_nll(mean, log_std, target, beta=0.5)) == pytest.approx((first + 2 * second) / 2, rel=1e-6)


def test_gaussian_nll_sums_dimensions():
    value = gaussian_nll(jnp.zeros((1, 2)), jnp.zeros((1, 2)), jnp.array([[1.0, 3.0]]))
    assert float(value) == pytest.approx(0.5 + 4.5 + 2 * HALF_LOG_2PI, rel=1e-6)


def test_beta_scales_the_mean_gradient():
    target, log_std = jnp.array([[2.0]]), jnp.array([[np.log(2.0)]])
    grad = lambda beta: float(jax.grad(lambda m: gaussian_nll(m, log_std, target, beta))(jnp.zeros((1, 1)))[0, 0])
    assert grad(0.0) == pytest.approx(-(2.0 - 0.0) / 4.0, rel=1e-6)  # -(target - mean) / std^2
    assert grad(1.0) == pytest.approx(-(2.0 - 0.0), rel=1e-6)  # the squared error's gradient, whatever the std
    # the weight is held constant: the log-std gradient is the NLL's, 1 - z^2, scaled by std^(2 beta)
    far = jnp.array([[4.0]])  # z = 4 / 2 = 2
    g_std = lambda beta: float(jax.grad(lambda s: gaussian_nll(jnp.zeros((1, 1)), s, far, beta))(log_std)[0, 0])
    assert g_std(0.0) == pytest.approx(1.0 - 4.0, rel=1e-6)
    assert g_std(1.0) == pytest.approx(4.0 * (1.0 - 4.0), rel=1e-6)


def test_cross_entropy_by_hand():
    logits = jnp.array([[0.0, 0.0], [np.log(3.0), 0.0]])  # softmax [1/2, 1/2] and [3/4, 1/4]
    target = jnp.array([0, 1])
    assert float(cross_entropy(logits, target)) == pytest.approx((np.log(2.0) + np.log(4.0)) / 2, rel=1e-6)


def test_cross_entropy_is_zero_for_certain_correct_predictions():
    assert float(cross_entropy(jnp.array([[50.0, -50.0, -50.0]]), jnp.array([0]))) == pytest.approx(0.0, abs=1e-6)


def test_mixture_nll_by_hand_and_with_one_component():
    means = jnp.array([[[0.0], [4.0]]])  # one sample, M = 2 components, d = 1
    log_stds = jnp.zeros((1, 2, 1))
    logits = jnp.log(jnp.array([[0.25, 0.75]]))
    target = jnp.array([[4.0]])
    density = 0.25 * np.exp(-8.0) / np.sqrt(2 * np.pi) + 0.75 / np.sqrt(2 * np.pi)  # z = 4 and z = 0
    assert float(mixture_nll(logits, means, log_stds, target)) == pytest.approx(-np.log(density), rel=1e-6)
    # one component is the plain Gaussian NLL
    mean, log_std, target = jnp.array([[0.5, -1.0]]), jnp.array([[0.2, -0.3]]), jnp.array([[1.0, 2.0]])
    assert float(mixture_nll(jnp.zeros((1, 1)), mean[:, None], log_std[:, None], target)) == pytest.approx(
        float(gaussian_nll(mean, log_std, target)), rel=1e-6)


def test_mixture_nll_prefers_a_component_on_each_mode_to_one_between_them():
    target = jnp.array([[-1.0], [1.0]])  # two demonstrations, two modes
    log_stds = jnp.full((2, 2, 1), np.log(0.1))
    logits = jnp.zeros((2, 2))
    on_modes = jnp.broadcast_to(jnp.array([[-1.0], [1.0]]), (2, 2, 1))
    between = jnp.zeros((2, 2, 1))
    assert float(mixture_nll(logits, on_modes, log_stds, target)) < float(
        mixture_nll(logits, between, log_stds, target)) - 10
