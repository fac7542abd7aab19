"""Synthetic item streams for buffer tests: B arenas running episodes of random lengths."""

import numpy as np


def episode_stream(num_arenas: int, num_steps: int, seed: int = 0, max_len: int = 9, id_base: int = 0) -> dict:
    """Items of ``num_steps`` steps of ``num_arenas`` arenas, leaves (T, B, ...) (time-major, like rollouts).

    Each arena runs episodes of 1..max_len steps; ``x`` encodes (episode, step) so tests can check contents.
    Episode ids are unique per arena and stream.
    """
    rng = np.random.default_rng(seed)
    episode = np.zeros((num_steps, num_arenas), np.int32)
    step = np.zeros((num_steps, num_arenas), np.int32)
    done = np.zeros((num_steps, num_arenas), bool)
    for a in range(num_arenas):
        t, eid = 0, id_base + 1000 * a
        while t < num_steps:
            length = int(rng.integers(1, max_len + 1))
            n = min(length, num_steps - t)
            episode[t:t + n, a] = eid
            step[t:t + n, a] = np.arange(n)
            done[t + n - 1, a] = n == length
            t, eid = t + n, eid + 1
    truncated = done & (rng.random(done.shape) < 0.5)
    x = np.stack([episode, step], -1).astype(np.float32)
    return {"episode": episode, "step": step, "terminated": done & ~truncated, "truncated": truncated, "x": x}


def stored(stream: dict, capacity_per_arena: int) -> dict:
    """The items a ring of ``capacity_per_arena`` per arena holds after adding ``stream``, oldest first."""
    return {k: v[-capacity_per_arena:] for k, v in stream.items()}


def item(stream: dict) -> dict:
    return {k: v[0, 0] for k, v in stream.items()}
