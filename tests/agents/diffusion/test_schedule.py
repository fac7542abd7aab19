"""The diffusion process against numbers worked by hand from its definitions."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena_agents.diffusion import schedule


def cosine(s):
    """squaredcos_cap_v2's f(s) = cos((s + 0.008) / 1.008 * pi / 2)^2."""
    return math.cos((s + 0.008) / 1.008 * math.pi / 2) ** 2


def test_squaredcos_cap_v2_alphas_cumprod():
    a = schedule.cosine_alphas_cumprod(100)
    assert a.shape == (100,) and a.dtype == np.float32
    # the product of (1 - beta_i) telescopes to f((t + 1) / T) / f(0) while no beta is capped ...
    for t, expected in [(0, 0.99936872), (1, 0.99825249), (10, 0.96671670), (50, 0.47826463), (98, 2.4285723e-4)]:
        assert math.isclose(cosine((t + 1) / 100) / cosine(0.0), expected, rel_tol=1e-7)
        np.testing.assert_allclose(a[t], expected, rtol=2e-6)
    # ... and the last step's beta is capped at 0.999 (uncapped it would be 1: nothing of the sample left)
    np.testing.assert_allclose(a[99], 2.4285723e-4 * (1 - 0.999), rtol=2e-6)
    assert np.all(np.diff(a) < 0)


def test_one_ddim_step_and_the_visited_steps():
    np.testing.assert_array_equal(schedule.ddim_timesteps(100, 10), [90, 80, 70, 60, 50, 40, 30, 20, 10, 0])
    np.testing.assert_array_equal(schedule.ddim_timesteps(100, 3), [66, 33, 0])
    with pytest.raises(ValueError, match=r"inference steps must lie in \[1, 100\]"):
        schedule.ddim_timesteps(100, 101)
    a = schedule.cosine_alphas_cumprod(100)
    a50, a40 = float(a[50]), float(a[40])
    # x_t = 0.3 and predicted noise 0.5 at t = 50: x_0 = (0.3 - sqrt(1 - a50) 0.5) / sqrt(a50) = -0.0884 (in [-1, 1]),
    # then x_40 = sqrt(a40) x_0 + sqrt(1 - a40) 0.5
    clean = (0.3 - math.sqrt(1 - a50) * 0.5) / math.sqrt(a50)
    assert math.isclose(clean, -0.08843, abs_tol=1e-4)
    inside = math.sqrt(a40) * clean + math.sqrt(1 - a40) * 0.5
    # x_t = 2 and noise -0.5: x_0 = 3.41 is clipped to 1
    clipped = math.sqrt(a40) * 1.0 + math.sqrt(1 - a40) * -0.5
    unclipped = math.sqrt(a40) * (2.0 + math.sqrt(1 - a50) * 0.5) / math.sqrt(a50) + math.sqrt(1 - a40) * -0.5

    @jax.jit
    def steps():
        sample, noise = jnp.array([0.3, 2.0]), jnp.array([0.5, -0.5])
        return (schedule.ddim_step(a, sample, noise, 50, 40), schedule.ddim_step(a, sample, noise, 50, 40, clip=False),
                schedule.ddim_step(a, sample, noise, 50, -10))  # past step 0: the clean estimate itself

    clip_on, clip_off, last = steps()
    np.testing.assert_allclose(clip_on, [inside, clipped], rtol=1e-5)
    np.testing.assert_allclose(clip_off, [inside, unclipped], rtol=1e-5)
    np.testing.assert_allclose(last, [clean, 1.0], rtol=1e-5)


def test_one_ddpm_step():
    """Ancestral DDPM with the posterior's fixed small variance (diffusers' DDPMScheduler, Diffusion Policy's
    sampler), worked from its definitions: x_t = 0.3, predicted noise 0.5, drawn noise -1.2, at t = 50."""
    a = schedule.cosine_alphas_cumprod(100)
    a50, a49, a40 = float(a[50]), float(a[49]), float(a[40])
    clean = (0.3 - math.sqrt(1 - a50) * 0.5) / math.sqrt(a50)

    def by_hand(a_prev, x0, drawn):
        alpha = a50 / a_prev
        beta = 1 - alpha
        mean = math.sqrt(a_prev) * beta / (1 - a50) * x0 + math.sqrt(alpha) * (1 - a_prev) / (1 - a50) * 0.3
        return mean + math.sqrt((1 - a_prev) / (1 - a50) * beta) * drawn

    step = jax.jit(schedule.ddpm_step, static_argnames="clip")
    sample, epsilon = jnp.array([0.3]), jnp.array([0.5])
    np.testing.assert_allclose(step(a, sample, epsilon, 50, 49, jnp.array([-1.2])), [by_hand(a49, clean, -1.2)],
                               rtol=1e-5)
    # ten training steps in one (10 inference steps of 100): the same posterior between t = 50 and t = 40
    np.testing.assert_allclose(step(a, sample, epsilon, 50, 40, jnp.array([-1.2])), [by_hand(a40, clean, -1.2)],
                               rtol=1e-5)
    # x_t = 2, noise -0.5: x_0 = 3.41 is clipped to 1 (with clip) for the mean
    big = (2.0 + math.sqrt(1 - a50) * 0.5) / math.sqrt(a50)
    hand_clipped = (math.sqrt(a49) * (1 - a50 / a49) / (1 - a50) * 1.0
                    + math.sqrt(a50 / a49) * (1 - a49) / (1 - a50) * 2.0)
    np.testing.assert_allclose(step(a, jnp.array([2.0]), jnp.array([-0.5]), 50, 49, jnp.zeros(1)), [hand_clipped],
                               rtol=1e-5)
    assert big > 1.0
    # the last step (t = 0, to the clean data) adds no noise: it lands on the posterior mean, the clean estimate
    a0 = float(a[0])
    x0 = (0.3 - math.sqrt(1 - a0) * 0.5) / math.sqrt(a0)
    np.testing.assert_allclose(step(a, sample, epsilon, 0, -1, jnp.array([5.0])), [x0], rtol=1e-5)


def test_forward_noise_and_ema_warm_up():
    a = schedule.cosine_alphas_cumprod(100)

    @jax.jit
    def values():
        noisy = schedule.add_noise(a, jnp.full((2, 3), 0.5), jnp.ones((2, 3)), jnp.array([0, 50]))
        decays = jnp.stack([schedule.ema_decay(n, 0.75, 0.9999) for n in (0, 1, 2, 10, 10**7)])
        average = schedule.ema_update({"w": jnp.zeros(2)}, {"w": jnp.ones(2)}, decays[3])
        return noisy, decays, average["w"]

    noisy, decays, average = values()
    for row, t in enumerate((0, 50)):
        np.testing.assert_allclose(noisy[row], 0.5 * math.sqrt(a[t]) + math.sqrt(1 - a[t]), rtol=1e-6)
    # Diffusion Policy's warm-up: n = update - 1; 0 until n > 0, then 1 - (1 + n)^-0.75, capped at 0.9999
    np.testing.assert_allclose(decays, [0.0, 0.0, 1 - 2 ** -0.75, 1 - 10 ** -0.75, 0.9999], rtol=1e-6)
    np.testing.assert_allclose(average, 10 ** -0.75, rtol=1e-5)  # 0.82 of the old average (0) and 0.18 of the new
