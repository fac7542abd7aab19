"""DreamerV3's actor-critic objectives against hand-computed values."""

import jax
import jax.numpy as jnp
import numpy as np

from jarena_agents.dreamer import losses
from jarena_agents.world_model import distributions as dist


def test_lambda_returns_by_hand():
    rewards = jnp.array([[0.0], [1.0], [2.0]])  # index 0 is the start: its reward is unused
    continues = jnp.array([[1.0], [1.0], [0.0]])  # the episode ends on arriving at step 2
    values = jnp.array([[0.0], [10.0], [20.0]])
    returns = losses.lambda_returns(rewards, continues, values, discount=0.9, lam=0.5)
    # R_1 = 2 + 0.9 * 0 * (...) = 2;  R_0 = 1 + 0.9 * 1 * (0.5 * 10 + 0.5 * 2) = 6.4
    np.testing.assert_allclose(returns[:, 0], [6.4, 2.0], rtol=1e-6)
    # lambda = 1: the discounted sum of rewards, bootstrapped with the last value
    alive = jnp.ones((4, 1))
    mc = losses.lambda_returns(jnp.array([[0.0], [1.0], [1.0], [1.0]]), alive, jnp.full((4, 1), 5.0), 0.5, 1.0)
    np.testing.assert_allclose(mc[:, 0], [1 + 0.5 + 0.25 + 0.125 * 5, 1 + 0.5 + 0.25 * 5, 1 + 0.5 * 5], rtol=1e-6)
    # lambda = 0: one-step TD targets
    td = losses.lambda_returns(rewards, alive[:3], values, 0.9, 0.0)
    np.testing.assert_allclose(td[:, 0], [1 + 0.9 * 10, 2 + 0.9 * 20], rtol=1e-6)


def test_trajectory_weights():
    continues = jnp.array([[0.0], [1.0], [0.5], [1.0]])  # the start's flag is ignored: the start counts 1
    np.testing.assert_allclose(losses.trajectory_weights(continues, 0.9)[:, 0], [1.0, 0.9, 0.9 * 0.9 * 0.5],
                               rtol=1e-6)


def test_return_scale_tracks_the_percentile_range_and_never_scales_up():
    returns = jnp.arange(101.0)  # P5 = 5, P95 = 95
    once = losses.ReturnScale.create().update(returns)
    np.testing.assert_allclose([once.low, once.high], [0.05, 0.95], rtol=1e-5)
    assert once.scale == 1.0  # a range below 1 divides by 1
    scale = losses.ReturnScale.create()
    for _ in range(2000):
        scale = scale.update(returns)
    np.testing.assert_allclose(scale.scale, 90.0, rtol=1e-3)


def test_actor_loss_is_reinforce_with_an_entropy_bonus():
    log_probs = jnp.array([[-1.0, -2.0]])
    entropies = jnp.array([[0.5, 0.5]])
    returns, values = jnp.array([[3.0, 1.0]]), jnp.array([[1.0, 1.0]])
    weights = jnp.ones((1, 2))
    loss = losses.actor_loss(log_probs, entropies, returns, values, weights, jnp.array(2.0), entropy_coef=0.1)
    # advantages (3 - 1) / 2 = 1 and 0: -mean(1 * -1 + 0.1 * 0.5, 0 * -2 + 0.1 * 0.5) = -mean(-0.95, 0.05)
    np.testing.assert_allclose(loss, 0.45, rtol=1e-6)
    grad = jax.grad(lambda lp: losses.actor_loss(lp, entropies, returns, values, weights, jnp.array(2.0)))(log_probs)
    np.testing.assert_allclose(grad, [[-0.5, 0.0]], atol=1e-7)  # the advantage is a constant


def test_the_backprop_actor_loss_maximises_the_advantage_itself():
    entropies = jnp.array([[0.5, 0.5]])
    returns, values = jnp.array([[3.0, 1.0]]), jnp.array([[1.0, 1.0]])
    weights = jnp.array([[1.0, 0.5]])
    loss = losses.backprop_actor_loss(entropies, returns, values, weights, jnp.array(2.0), entropy_coef=0.1)
    # -mean(1 * ((3 - 1) / 2 + 0.05), 0.5 * (0 + 0.05)) = -mean(1.05, 0.025)
    np.testing.assert_allclose(loss, -0.5375, rtol=1e-6)
    grads = jax.grad(lambda r, v, w, s: losses.backprop_actor_loss(entropies, r, v, w, s), argnums=(0, 1, 2, 3))(
        returns, values, weights, jnp.array(2.0))
    np.testing.assert_allclose(grads[0], [[-0.25, -0.125]], atol=1e-7)  # -w / (scale N): returns carry gradients
    np.testing.assert_allclose(grads[1], [[0.25, 0.125]], atol=1e-7)
    assert not np.any(grads[2]) and not np.any(grads[3])  # weights and scale are constants


def test_critic_loss_and_slow_critic():
    centres = dist.bins(5, -2.0, 2.0)
    logits = jnp.zeros((2, 3, 5))
    loss = losses.critic_loss(logits, jnp.ones((2, 3)), jnp.zeros((2, 3)), jnp.ones((2, 3)), centres)
    np.testing.assert_allclose(loss, 2 * np.log(5), rtol=1e-6)  # uniform logits: log K for each of the two targets
    slow = losses.ema({"w": jnp.zeros(2)}, {"w": jnp.ones(2)}, 0.02)
    np.testing.assert_allclose(slow["w"], 0.02)
