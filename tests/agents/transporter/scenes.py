"""Small synthetic tabletops for the transporter's tests, and infos that hold given observations."""

import math

import numpy as np

from jarena.core.types import Info

ROWS, COLS = 24, 16
L_SHAPE = np.array([(0, 0), (1, 0), (2, 0), (0, 1)])  # cells from the pick point, (row, column)
OBJECT, TARGET = (255, 87, 89), (80, 80, 255)


def quarter_turns(cells: np.ndarray, k: int) -> np.ndarray:
    """Cells turned by k quarter turns of yaw: +x (a column right) to +y (a row down), (dr, dc) -> (dc, -dr)."""
    for _ in range(k % 4):
        cells = np.stack([cells[:, 1], -cells[:, 0]], -1)
    return cells


def scenes(count: int, seed: int) -> dict:
    """Tables with an L-shaped object (red, 4 cm high) at a random heading and its target (blue, 1 cm), the same L
    turned by a random number of quarter turns more, elsewhere. The demonstration picks the L's corner and puts it on
    the target's corner, turned by those quarter turns: ``{"rgb", "height", "action"}``."""
    rng = np.random.default_rng(seed)
    rgb = np.full((count, ROWS, COLS, 3), 51, np.uint8)
    height = np.zeros((count, ROWS, COLS), np.float32)
    action = np.zeros((count, 5), np.float32)
    for i in range(count):
        heading, turn = rng.integers(4, size=2)
        while True:
            pick, place = rng.integers(3, [ROWS - 3, COLS - 3], size=(2, 2))
            if np.abs(pick - place).max() > 6:
                break
        for cell in pick + quarter_turns(L_SHAPE, heading):
            rgb[i, cell[0], cell[1]], height[i, cell[0], cell[1]] = OBJECT, 0.04
        for cell in place + quarter_turns(L_SHAPE, heading + turn):
            rgb[i, cell[0], cell[1]], height[i, cell[0], cell[1]] = TARGET, 0.01
        action[i] = [*pick, *place, math.remainder(turn * math.pi / 2, 2 * math.pi)]
    return dict(rgb=rgb, height=height, action=action)


def infos(observation: dict) -> Info:
    """Infos of a batch of ``observation`` (every other field zeros: the agent reads only the images)."""
    count = len(observation["rgb"])
    zeros = np.zeros(count, np.float32)
    return Info(observation=observation, reward=zeros, terminated=zeros.astype(bool), truncated=zeros.astype(bool),
                success=zeros.astype(bool), goal=np.zeros((count, 0), np.float32), step=zeros.astype(np.int32),
                episode=zeros.astype(np.int32), fault=zeros.astype(np.int32))
