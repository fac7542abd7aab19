"""symlog, two-hot regression and categorical latents against hand-computed values."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena_agents.world_model import distributions as dist


def test_symlog_and_symexp():
    x = jnp.array([-(np.e - 1), 0.0, np.e - 1, 1e6])
    np.testing.assert_allclose(dist.symlog(x)[:3], [-1.0, 0.0, 1.0], atol=1e-6)
    np.testing.assert_allclose(dist.symexp(dist.symlog(x)), x, rtol=1e-5)


def test_dreamerv3_bins():
    centres = dist.bins()
    assert centres.shape == (255,) and centres[0] == -20 and centres[-1] == 20 and centres[127] == 0


def test_two_hot_splits_a_value_between_its_neighbours():
    centres = jnp.array([-1.0, 0.0, 1.0])
    y = dist.symexp(jnp.array([0.25, -1.0, 5.0, -0.5]))  # symlog 0.25: 3/4 on 0, 1/4 on 1; beyond: all on the edge
    np.testing.assert_allclose(dist.two_hot(y, centres), [[0, 0.75, 0.25], [1, 0, 0], [0, 0, 1], [0.5, 0.5, 0]],
                               atol=1e-6)
    # the prediction of the two-hot distribution itself is the value back
    logits = jnp.log(jnp.array([0.0, 0.75, 0.25]) + 1e-30)
    np.testing.assert_allclose(dist.two_hot_mean(logits, centres), dist.symexp(0.25), rtol=1e-5)
    # uniform logits: cross-entropy log K whatever the target
    np.testing.assert_allclose(dist.two_hot_loss(jnp.zeros((2, 3)), jnp.array([0.3, -7.0]), centres), np.log(3),
                               rtol=1e-6)


def test_unimix_keeps_every_class_possible():
    probs = dist.categorical_probs(jnp.array([[100.0, -100.0]]))
    np.testing.assert_allclose(probs, [[0.995, 0.005]], atol=1e-6)
    np.testing.assert_allclose(dist.categorical_probs(jnp.zeros((1, 4))), 0.25, atol=1e-7)


def test_categorical_kl_and_entropy_sum_over_variables():
    p = jnp.array([[0.5, 0.5], [0.9, 0.1]])  # two variables of two classes
    q = jnp.array([[0.9, 0.1], [0.9, 0.1]])
    expected = 0.5 * np.log(0.5 / 0.9) + 0.5 * np.log(0.5 / 0.1)  # the second variable contributes 0
    np.testing.assert_allclose(dist.categorical_kl(p, q), expected, rtol=1e-6)
    np.testing.assert_allclose(dist.categorical_entropy(p), np.log(2) - 0.9 * np.log(0.9) - 0.1 * np.log(0.1),
                               rtol=1e-6)


def test_one_hot_samples_pass_the_gradient_of_the_probabilities():
    probs = jnp.array([[0.2, 0.3, 0.5]])
    weights = jnp.array([1.0, 2.0, 3.0])
    sample = dist.sample_one_hot(jax.random.key(0), probs)
    assert sorted(np.asarray(sample)[0].round(6).tolist()) == [0.0, 0.0, 1.0]
    grad = jax.grad(lambda p: jnp.sum(dist.sample_one_hot(jax.random.key(0), p) * weights))(probs)
    np.testing.assert_allclose(grad, weights[None], rtol=1e-6)
    np.testing.assert_allclose(dist.mode_one_hot(probs), [[0, 0, 1]], atol=1e-6)
    counts = jnp.mean(dist.sample_one_hot(jax.random.key(1), jnp.broadcast_to(probs, (20000, 3))), 0)
    np.testing.assert_allclose(counts, probs[0], atol=0.015)


@pytest.mark.parametrize("target, expected", [(1.0, np.log(2)), (0.0, np.log(2))])
def test_bernoulli_loss(target, expected):
    np.testing.assert_allclose(dist.bernoulli_loss(jnp.array(0.0), jnp.array(target)), expected, rtol=1e-6)
    np.testing.assert_allclose(dist.bernoulli_loss(jnp.array(2.0), jnp.array(1.0)), np.log1p(np.exp(-2.0)), rtol=1e-6)
