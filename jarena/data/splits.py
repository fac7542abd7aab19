"""Splitting a dataset into train / val / test by whole trajectory."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from jarena.data.schema import DatasetError

DEFAULT_NAMES = ("train", "val", "test")


def split_trajectories(num_trajectories: int, ratios: Sequence[float] | Mapping[str, float] = (0.8, 0.1, 0.1),
                       seed: int = 0) -> dict[str, np.ndarray]:
    """Assigns each trajectory index to exactly one split.

    Args:
      num_trajectories: N.
      ratios: fractions summing to 1, as ``(train, val, test)``, ``(train, val)``, or a dict by split name.
      seed: the shuffle's seed; the result is a pure function of ``(N, ratios, seed)``.

    Returns:
      ``{name: sorted int64 indices}``; sizes are ``ratio * N`` rounded by largest remainder, so they sum
      to N. Appending trajectories changes the assignment: split once collection is done.
    """
    if isinstance(ratios, Mapping):
        names, values = list(ratios), [ratios[k] for k in ratios]
    else:
        values = list(ratios)
        if len(values) not in (2, 3):
            raise DatasetError(f"ratios must be (train, val), (train, val, test) or a dict by name, got {ratios!r}")
        names = list(DEFAULT_NAMES[:len(values)])
    values = np.asarray(values, np.float64)
    if np.any(values < 0) or not np.isclose(values.sum(), 1.0, atol=1e-6):
        given = dict(zip(names, values.tolist(), strict=True))
        raise DatasetError(f"split ratios must be non-negative and sum to 1, got {given}")
    exact = values * num_trajectories
    counts = np.floor(exact).astype(np.int64)
    remainder = num_trajectories - int(counts.sum())
    counts[np.argsort(-(exact - counts), kind="stable")[:remainder]] += 1
    order = np.random.default_rng(seed).permutation(num_trajectories)
    bounds = np.concatenate([[0], np.cumsum(counts)])
    return {name: np.sort(order[a:b]).astype(np.int64) for name, a, b in zip(names, bounds[:-1], bounds[1:],
                                                                             strict=True)}
