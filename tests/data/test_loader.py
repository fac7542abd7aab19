import collections

import jax
import numpy as np
import pytest
from trajectories import ACT, GOAL, OBS, length_of, trajectory

from jarena.data import DatasetError, Loader, TrajectoryDataset

N = 12


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    path = tmp_path_factory.mktemp("loader") / "demos"
    with TrajectoryDataset(path, "w", obs_config=OBS, act_config=ACT, goal_config=GOAL, chunk_bytes=512) as ds:
        ds.add_trajectories([trajectory(k) for k in range(N)])
    return TrajectoryDataset(path)


def _equal(a, b):
    jax.tree_util.tree_map(np.testing.assert_array_equal, a, b)


MODES = [("transition", None), ("window", 3), ("window_across", 5), ("trajectory", None)]


@pytest.mark.parametrize("mode, length", MODES)
def test_in_memory_and_streamed_batches_are_the_same(dataset, mode, length):
    train = dataset.split((0.75, 0.25), seed=1)["train"]
    memory = dataset.loader(6, mode=mode, length=length, trajectories=train, memory_budget=1 << 30)
    stream = dataset.loader(6, mode=mode, length=length, trajectories=train, memory_budget=2000)
    assert memory.in_memory and not stream.in_memory and stream.nbytes == memory.nbytes > 2000
    for x, y in zip(memory.batches(jax.random.key(0), 4), stream.batches(jax.random.key(0), 4), strict=True):
        _equal(x, y)
        assert set(np.asarray(x["trajectory"]).ravel()) <= set(train.tolist())
    assert stream._cache.used <= 2000 + max((a.nbytes for a in stream._cache.chunks.values()), default=0)
    _equal(dataset.sample(jax.random.key(7), 6, mode=mode, length=length, trajectories=train),
           memory.sample(jax.random.key(7)))


def test_compressed_fields_stream_through_a_chunk_cache(tmp_path):
    obs = {"rgb": dict(OBS["rgb"], compression="zstd"), "state": OBS["state"]}
    with TrajectoryDataset(tmp_path / "z", "w", obs_config=obs, act_config=ACT, goal_config=GOAL,
                           chunk_bytes=512) as ds:
        ds.add_trajectories([trajectory(k) for k in range(N)])
        memory = ds.loader(8, mode="window", length=2, memory_budget=1 << 30)
        stream = ds.loader(8, mode="window", length=2, memory_budget=3000)
        for i in range(3):
            _equal(memory.sample(jax.random.key(i)), stream.sample(jax.random.key(i)))
        assert stream._cache.chunks  # the compressed rgb chunks went through the cache


def _expected_step(k, step):
    t = trajectory(k)
    return t["observations"]["state"][step], t["observations"]["state"][step + 1], t["actions"]["force"][step]


def test_transitions_match_the_stored_trajectories_and_are_uniform(dataset):
    loader = dataset.loader(64, memory_budget=1 << 30)
    seen = collections.Counter()
    for batch in loader.batches(jax.random.key(1), 30):
        batch = jax.tree_util.tree_map(np.asarray, batch)
        assert batch["observation"]["image"].dtype == np.uint8 and batch["action"]["force"].shape == (64, 2)
        for i in range(64):
            k, s = int(batch["trajectory"][i]), int(batch["step"][i])
            obs, nxt, act = _expected_step(k, s)
            np.testing.assert_array_equal(batch["observation"]["state"][i], obs)
            np.testing.assert_array_equal(batch["next_observation"]["state"][i], nxt)
            np.testing.assert_array_equal(batch["action"]["force"][i], act)
            np.testing.assert_array_equal(batch["goal"]["goal"][i], [k, -k])
            assert batch["last"][i] == (s == length_of(k) - 1) and batch["first"][i] == (s == 0)
            seen[k, s] += 1
    assert len(seen) == dataset.num_steps()
    chi2 = sum((c - 30 * 64 / len(seen)) ** 2 / (30 * 64 / len(seen)) for c in seen.values())
    assert chi2 < len(seen) - 1 + 5 * np.sqrt(2 * (len(seen) - 1))


def test_windows_stay_in_one_trajectory_and_across_windows_flag_boundaries(dataset):
    within = jax.tree_util.tree_map(np.asarray, dataset.loader(200, mode="window", length=4).sample(jax.random.key(2)))
    assert (within["trajectory"] == within["trajectory"][:, :1]).all()
    assert (np.diff(within["step"], axis=1) == 1).all() and within["mask"].all()
    assert all(length_of(k) >= 4 for k in within["trajectory"][:, 0])
    across = jax.tree_util.tree_map(np.asarray, dataset.loader(200, mode="window_across", length=6)
                                    .sample(jax.random.key(3)))
    changes = np.diff(across["trajectory"], axis=1) != 0
    np.testing.assert_array_equal(changes, across["last"][:, :-1])
    np.testing.assert_array_equal(changes, across["first"][:, 1:])
    assert changes.any()


def test_trajectories_are_padded_with_a_mask(dataset):
    batch = jax.tree_util.tree_map(np.asarray, dataset.loader(20, mode="trajectory").sample(jax.random.key(4)))
    assert batch["mask"].shape == (20, max(map(length_of, range(N))))
    for i in range(20):
        k = int(batch["trajectory"][i, 0])
        t = length_of(k)
        assert batch["mask"][i].sum() == t and batch["mask"][i, :t].all()
        np.testing.assert_array_equal(batch["observation"]["state"][i, :t], trajectory(k)["observations"]["state"][:t])
        assert (batch["observation"]["state"][i, t:] == 0).all() and (batch["reward"][i, t:] == 0).all()
        assert batch["last"][i, t - 1] and batch["terminated"][i, t - 1]


def test_bad_loader_arguments(dataset):
    with pytest.raises(DatasetError, match="valid modes are"):
        Loader(dataset, 4, mode="episodes")
    with pytest.raises(DatasetError, match="needs a positive length"):
        dataset.loader(4, mode="window")
    with pytest.raises(DatasetError, match="no window of length 50"):
        dataset.loader(4, mode="window", length=50)
    with pytest.raises(DatasetError, match=r"must lie in \[0, 12\)"):
        dataset.loader(4, trajectories=[0, 12])
    with pytest.raises(DatasetError, match="nothing to sample"):
        dataset.loader(4, trajectories=[])
