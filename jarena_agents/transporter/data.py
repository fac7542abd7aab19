"""Transporter's demonstrations: the image before each pick-and-place and the action taken, read whole from a
TrajectoryDataset."""

from __future__ import annotations

from typing import Any

import numpy as np

from jarena.core.arena import Arena
from jarena.data.dataset import TrajectoryDataset
from jarena_agents.datasets import check_dataset


def read_dataset(path: str, arena: Arena, keys: tuple[str, str]) -> dict[str, Any]:
    """Every step of the dataset at ``path`` as numpy arrays: ``{"rgb": uint8 (S, H, W, 3), "height": float32
    (S, H, W), "action": float32 (S, 5)}`` for the observation fields ``keys`` (colour, height) seen before each
    of the S actions (the observation after a trajectory's last action is not read into memory)."""
    if not path:
        raise ValueError("transporter needs demonstrations: set its config key dataset=PATH to a TrajectoryDataset "
                         "(collect one with `jarena collect oracle_raven ARENA --out PATH`)")
    with TrajectoryDataset(path, "r") as dataset:
        check_dataset(dataset, arena, "transporter", ("observation", "action"), need="steps")
        lengths = dataset.lengths()
        n, steps = dataset.num_trajectories(), dataset.num_steps()
        (action_name,) = dataset.schema.action
        action = dataset.rows(f"action/{action_name}", 0, steps)
        # trajectory i's T_i + 1 observations start at row (its first action's row) + i
        first = np.repeat(np.cumsum(lengths) - lengths + np.arange(n), lengths)
        rows = first + np.concatenate([np.arange(t) for t in lengths])
        colour, height = (dataset.rows(f"observation/{k}", 0, steps + n)[rows] for k in keys)
    return {"rgb": colour, "height": height.astype(np.float32), "action": action.reshape(steps, -1).astype(np.float32)}
