import numpy as np
import pytest

from jarena.data import DatasetError, split_trajectories


@pytest.mark.parametrize("n", [0, 1, 7, 10, 1001])
def test_splits_partition_the_trajectories_with_the_given_ratios(n):
    splits = split_trajectories(n, (0.8, 0.1, 0.1), seed=3)
    assert list(splits) == ["train", "val", "test"]
    together = np.concatenate(list(splits.values()))
    assert sorted(together.tolist()) == list(range(n))  # each trajectory in exactly one split
    for name, ratio in zip(splits, (0.8, 0.1, 0.1), strict=True):
        assert abs(len(splits[name]) - ratio * n) < 1
    assert split_trajectories(n, (0.8, 0.1, 0.1), seed=3)["val"].tolist() == splits["val"].tolist()


def test_seed_and_names():
    a = split_trajectories(100, {"fit": 0.5, "check": 0.5}, seed=0)
    b = split_trajectories(100, {"fit": 0.5, "check": 0.5}, seed=1)
    assert list(a) == ["fit", "check"] and a["fit"].tolist() != b["fit"].tolist()
    assert list(split_trajectories(10, (0.7, 0.3))) == ["train", "val"]


@pytest.mark.parametrize("ratios", [(0.5, 0.6), (1.2, -0.2, 0.0), (1.0,), (0.25,) * 4])
def test_bad_ratios(ratios):
    with pytest.raises(DatasetError, match="ratios"):
        split_trajectories(10, ratios)
