"""Transporter's demonstrations: the image before each pick-and-place and the action taken, read whole from a
TrajectoryDataset and put in Transporter's terms (:mod:`jarena_agents.transporter.layout`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from jarena.core.arena import Arena
from jarena.data.dataset import TrajectoryDataset
from jarena_agents.datasets import check_dataset
from jarena_agents.transporter import layout as layout_lib
from jarena_agents.transporter.layout import COLOR_KEY, Layout


def read_dataset(path: str, arena: Arena, layout: Layout) -> dict[str, Any]:
    """Every step of the dataset at ``path`` as numpy arrays: ``{"rgb": uint8 (S, H, W, 3), "height": float32
    (S, H, W) metres above the table, "action": float32 (S, 5)}``: the colour and height map
    (:func:`~jarena_agents.transporter.layout.height_map`) seen before each of the S actions (the observation after a
    trajectory's last action is not read into memory), and each action as Transporter's pick and place pixels and
    yaw (:func:`~jarena_agents.transporter.layout.from_arena_action`; continuous pixels, which the labels round)."""
    if not path:
        raise ValueError("transporter needs demonstrations: set its config key dataset=PATH to a TrajectoryDataset "
                         "(collect one with `jarena collect ORACLE ARENA --out PATH`, e.g. oracle_raven or "
                         "oracle_cloth_flattening)")
    keys = (COLOR_KEY,) + ((layout.height_key,) if layout.height_key else ())
    with TrajectoryDataset(path, "r") as dataset:
        check_dataset(dataset, arena, "transporter", ("observation", "action"), need="steps")
        lengths = dataset.lengths()
        n, steps = dataset.num_trajectories(), dataset.num_steps()
        (action_name,) = dataset.schema.action
        action = dataset.rows(f"action/{action_name}", 0, steps).reshape(steps, -1)
        # trajectory i's T_i + 1 observations start at row (its first action's row) + i
        first = np.repeat(np.cumsum(lengths) - lengths + np.arange(n), lengths)
        rows = first + np.concatenate([np.arange(t) for t in lengths])
        observation = {k: dataset.rows(f"observation/{k}", 0, steps + n)[rows] for k in keys}
    return {"rgb": observation[COLOR_KEY],
            "height": np.asarray(layout_lib.height_map(observation, layout), np.float32),
            "action": np.asarray(layout_lib.from_arena_action(action, layout), np.float32)}
