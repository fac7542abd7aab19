"""PPO kernels checked against hand-worked values and a plain-Python reference."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena_agents.ppo.losses import compute_gae, ppo_loss


def gae_reference(rewards, values, next_values, terminated, done, gamma, lam):
    T, B = rewards.shape
    adv = np.zeros((T, B))
    for b in range(B):
        running = 0.0
        for t in reversed(range(T)):
            delta = rewards[t, b] + gamma * (1 - terminated[t, b]) * next_values[t, b] - values[t, b]
            running = delta + gamma * lam * (1 - done[t, b]) * running
            adv[t, b] = running
    return adv


def test_gae_hand_worked():
    # One arena, three steps, gamma = 0.5, lambda = 0.5, no episode end:
    # deltas: 1 + .5*2 - 1 = 1;  0 + .5*3 - 2 = -0.5;  2 + .5*4 - 3 = 1
    # A2 = 1;  A1 = -0.5 + .25*1 = -0.25;  A0 = 1 + .25*(-0.25) = 0.9375
    r = jnp.array([[1.0], [0.0], [2.0]])
    v = jnp.array([[1.0], [2.0], [3.0]])
    nv = jnp.array([[2.0], [3.0], [4.0]])
    f = jnp.zeros((3, 1), bool)
    adv, ret = compute_gae(r, v, nv, f, f, 0.5, 0.5)
    np.testing.assert_allclose(adv[:, 0], [0.9375, -0.25, 1.0])
    np.testing.assert_allclose(ret[:, 0], [1.9375, 1.75, 4.0])


def test_gae_termination_and_truncation():
    r = jnp.array([[1.0], [1.0], [1.0]])
    v = jnp.array([[1.0], [1.0], [1.0]])
    nv = jnp.array([[5.0], [7.0], [1.0]])
    # step 0 terminates: no bootstrap, no carry from step 1 -> A0 = 1 - 1 = 0
    # step 1 is truncated: bootstrap from next value 7 (the final observation), no carry -> A1 = 1 + .5*7 - 1
    term = jnp.array([[True], [False], [False]])
    done = jnp.array([[True], [True], [False]])
    adv, _ = compute_gae(r, v, nv, term, done, 0.5, 1.0)
    np.testing.assert_allclose(adv[:, 0], [0.0, 3.5, 0.5])


def test_gae_matches_reference_on_random_data():
    rng = np.random.default_rng(0)
    T, B = 17, 5
    r, v, nv = (rng.normal(size=(T, B)).astype(np.float32) for _ in range(3))
    term = rng.random((T, B)) < 0.1
    done = term | (rng.random((T, B)) < 0.1)
    adv, ret = jax.jit(compute_gae, static_argnums=(5, 6))(r, v, nv, term, done, 0.99, 0.95)
    expected = gae_reference(r, v, nv, term, done, 0.99, 0.95)
    np.testing.assert_allclose(adv, expected, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(ret, expected + v, rtol=1e-5, atol=1e-5)


def test_ppo_loss_hand_worked():
    # Two samples, advantages not normalised; ratios e^0.5 = 1.6487 (clipped to 1.2) and e^-0.5 = 0.6065.
    logp = jnp.array([0.5, -0.5])
    old = jnp.zeros(2)
    adv = jnp.array([1.0, 1.0])
    terms = ppo_loss(logp, old, adv, values=jnp.array([1.0, 3.0]), old_values=jnp.zeros(2),
                     returns=jnp.array([2.0, 1.0]), entropy=jnp.array([0.5, 1.5]), clip_epsilon=0.2,
                     value_coef=0.5, entropy_coef=0.1, normalize_advantages=False)
    policy = -(1.2 + np.exp(-0.5)) / 2
    value = 0.5 * (1.0 + 4.0) / 2
    assert float(terms.policy) == pytest.approx(policy, rel=1e-6)
    assert float(terms.value) == pytest.approx(value)
    assert float(terms.entropy) == pytest.approx(1.0)
    assert float(terms.total) == pytest.approx(policy + 0.5 * value - 0.1 * 1.0, rel=1e-6)
    assert float(terms.clip_fraction) == pytest.approx(1.0)  # both ratios outside [0.8, 1.2]


def test_ppo_loss_negative_advantage_clips_the_other_side():
    # With A < 0 the objective keeps the pessimistic (larger-loss) branch: ratio 0.5 is clipped to 0.8.
    terms = ppo_loss(jnp.log(jnp.array([0.5])), jnp.zeros(1), jnp.array([-2.0]), jnp.zeros(1), jnp.zeros(1),
                     jnp.zeros(1), jnp.zeros(1), normalize_advantages=False)
    assert float(terms.policy) == pytest.approx(0.8 * 2.0)


def test_ppo_loss_gradient_is_zero_outside_the_clip_region():
    def policy_loss(logp):
        return ppo_loss(logp, jnp.zeros(1), jnp.array([1.0]), jnp.zeros(1), jnp.zeros(1), jnp.zeros(1),
                        jnp.zeros(1), normalize_advantages=False).policy
    assert float(jax.grad(policy_loss)(jnp.array([0.5]))[0]) == 0.0
    assert float(jax.grad(policy_loss)(jnp.array([0.1]))[0]) == pytest.approx(-np.exp(0.1))
