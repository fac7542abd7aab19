import collections

import jax
import numpy as np
import pytest
from streams import episode_stream, item, stored

from jarena.data import make_buffer, sampling

B, C = 3, 40  # arenas, items per arena


@pytest.fixture(scope="module")
def stream():
    return episode_stream(B, 70, seed=3)  # more than C steps: the ring has wrapped


def _filled(stream, **kwargs):
    buffer = make_buffer(B, B * C, 64, **kwargs)
    state = jax.jit(buffer.add)(buffer.init(item(stream)), {k: v[:30] for k, v in stream.items()})
    state = jax.jit(buffer.add)(state, {k: v[30:] for k, v in stream.items()})
    return buffer, state


def _draw(buffer, state, n):
    sample = jax.jit(jax.vmap(buffer.sample, in_axes=(None, 0)))(state, jax.random.split(jax.random.key(0), n))
    return jax.tree_util.tree_map(lambda x: np.asarray(x).reshape((-1,) + x.shape[2:]), sample)


def _windows(kept, length, across):
    """All (arena, logical start) windows of `length` stored items, as tuples of (episode, step) pairs."""
    out = set()
    for a in range(B):
        for s in range(C - length + 1):
            ep, st = kept["episode"][s:s + length, a], kept["step"][s:s + length, a]
            if across or (np.all(ep == ep[0]) and np.all(np.diff(st) == 1)):
                out.add(tuple(zip(ep.tolist(), st.tolist(), strict=True)))
    return out


def _assert_uniform(counts):
    """Chi-square check that the draws are uniform over the keys seen (within 5 standard deviations)."""
    k, n = len(counts), sum(counts.values())
    chi2 = sum((c - n / k) ** 2 / (n / k) for c in counts.values())
    assert chi2 < (k - 1) + 5 * np.sqrt(2 * (k - 1)), (chi2, k)


def _as_keys(x):
    return [tuple(map(tuple, w.astype(int).tolist())) for w in x]


def test_transitions_are_uniform_over_stored_items(stream):
    buffer, state = _filled(stream)
    sample = _draw(buffer, state, 60)
    kept = stored(stream, C)
    assert sample.experience["x"].shape == (60 * 64, 2) and sample.mask.all()
    counts = collections.Counter(map(tuple, sample.experience["x"].astype(int).tolist()))
    assert set(counts) == set(map(tuple, kept["x"].reshape(-1, 2).astype(int).tolist()))
    _assert_uniform(counts)
    # first/done flags agree with the stored stream
    done = {tuple(x): bool(d) for x, d in zip(kept["x"].reshape(-1, 2).astype(int).tolist(),
                                                (kept["terminated"] | kept["truncated"]).reshape(-1), strict=True)}
    assert all(done[tuple(x)] == d for x, d in zip(sample.experience["x"].astype(int).tolist(), sample.done,
                                                    strict=True))


@pytest.mark.parametrize("length", [1, 4])
def test_windows_stay_inside_episodes_and_cover_all_uniformly(stream, length):
    buffer, state = _filled(stream, mode="window", length=length)
    sample = _draw(buffer, state, 40)
    x = sample.experience["x"]  # (N, L, 2): (episode, step)
    assert x.shape[1:] == (length, 2) and sample.mask.all()
    assert (x[:, :, 0] == x[:, :1, 0]).all() and (np.diff(x[:, :, 1], axis=1) == 1).all()
    counts = collections.Counter(_as_keys(x))
    assert set(counts) == _windows(stored(stream, C), length, across=False)
    _assert_uniform(counts)


def test_window_sampling_falls_back_to_exact_draws_when_windows_are_rare():
    # one arena, one 6-step episode among 1-step ones: only one valid window of length 6
    n = 30
    episode = np.arange(n, dtype=np.int32)
    episode[10:16] = 10
    step = np.zeros(n, np.int32)
    step[10:16] = np.arange(6)
    items = {"episode": episode[:, None], "step": step[:, None], "terminated": np.ones((n, 1), bool),
             "truncated": np.zeros((n, 1), bool)}
    buffer = make_buffer(1, n, 16, mode="window", length=6)
    state = jax.jit(buffer.add)(buffer.init(item(items)), items)
    sample = jax.jit(buffer.sample)(state, jax.random.key(1))
    assert sample.mask.all() and (np.asarray(sample.experience["step"]) == np.arange(6)).all()
    assert bool(buffer.can_sample(state))
    assert not bool(make_buffer(1, n, 16, mode="window", length=7).can_sample(state))


def test_windows_across_episodes_flag_boundaries(stream):
    buffer, state = _filled(stream, mode="window_across", length=5)
    sample = _draw(buffer, state, 30)
    x = sample.experience["x"]
    assert set(_as_keys(x)) == _windows(stored(stream, C), 5, across=True)
    kept = stored(stream, C)
    # first: the item starts its episode, or is the oldest item stored of it
    starts = {(int(e), int(s)) for e, s in kept["x"][0]} | {
        (int(e), int(s)) for e, s in kept["x"].reshape(-1, 2) if s == 0}
    np.testing.assert_array_equal(sample.first, [[tuple(p) in starts for p in w] for w in x.astype(int).tolist()])
    np.testing.assert_array_equal(sample.done, sample.experience["terminated"] | sample.experience["truncated"])
    assert sample.first.any() and sample.done.any()


@pytest.mark.parametrize("complete_only", [True, False])
def test_trajectories_are_whole_episodes_with_a_mask(stream, complete_only):
    buffer, state = _filled(stream, mode="trajectory", length=12, complete_only=complete_only)
    sample = _draw(buffer, state, 20)
    kept = stored(stream, C)
    x, mask = sample.experience["x"], sample.mask
    assert x.shape[1:] == (12, 2)
    assert (x[~mask] == 0).all()  # zero padding
    lengths = mask.sum(1)
    assert (mask == (np.arange(12) < lengths[:, None])).all()
    got = collections.Counter(tuple(map(tuple, w[:n].astype(int).tolist())) for w, n in zip(x, lengths, strict=True))
    # expected: stretches of one episode per arena; complete ones start at step 0 and end with done
    expect = set()
    for a in range(B):
        for s in range(C):
            if s > 0 and kept["episode"][s, a] == kept["episode"][s - 1, a]:
                continue
            e = s
            while e + 1 < C and kept["episode"][e + 1, a] == kept["episode"][s, a]:
                e += 1
            done = kept["terminated"][e, a] | kept["truncated"][e, a]
            if complete_only and not (kept["step"][s, a] == 0 and done):
                continue
            expect.add(tuple(map(tuple, kept["x"][s:e + 1, a].astype(int).tolist())))
    assert set(got) == expect
    _assert_uniform(got)
    assert sample.first[:, 0].all() and not sample.first[:, 1:].any()
    if complete_only:
        np.testing.assert_array_equal(sample.done, mask & (np.arange(12) == lengths[:, None] - 1))


def test_nothing_to_sample_gives_an_empty_mask():
    stream = episode_stream(2, 3, max_len=9)
    buffer = make_buffer(2, 20, 4, mode="trajectory", length=5)
    state = jax.jit(buffer.add)(buffer.init(item(stream)), {k: v[:1] for k, v in stream.items()})
    sample = jax.jit(buffer.sample)(state, jax.random.key(0))
    assert not bool(buffer.can_sample(state)) or sample.mask.any()
    empty = make_buffer(2, 20, 4).init(item(stream))
    assert not jax.jit(sampling.sample_transitions, static_argnums=2)(empty, jax.random.key(0), 4).mask.any()
