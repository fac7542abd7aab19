"""Write and read throughput (MB/s) of ``TrajectoryDataset`` against the disk's plain sequential writes.

Trajectories of ``--steps`` steps with a ``--image`` uint8 RGB observation, an 8-float state, a 4-float
action and the per-step scalars (about 1.25 MB each at the defaults) are written to a dataset in
``--dir``; a handful of distinct trajectories are made first and cycled, so the clock sees only the
dataset. Every write figure includes ``os.sync()`` at the end (the data is on disk); the plain
sequential write is 1 MiB blocks to one file in the same directory, then ``fsync``. Reads are cold
(the dataset's files are evicted from the page cache with ``posix_fadvise(DONTNEED)`` first) unless
marked warm.

Variants: one commit per trajectory (``add_trajectory``) or per group of 16 (``add_trajectories``), the
default 4 MiB chunks or 1 MiB chunks, raw or zstd, run ``--rounds`` times interleaved with the
plain write (the figures are medians, and each write's ratio to the plain write of its round); reads
of every trajectory (``get_trajectory``), the loader loading the whole dataset into memory, and the
streaming loader drawing windows.

Usage::

    python benchmarks/dataset_throughput.py --dir /tmp/bench --trajectories 200
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time

import jax
import numpy as np

try:
    import jarena
except ImportError:  # run from a checkout without installing
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import jarena

MB = 1e6


def make_trajectories(count: int, steps: int, image: int, seed: int = 0) -> list[dict]:
    rng = np.random.default_rng(seed)
    out = []
    for k in range(count):
        ramp = np.linspace(0, 200, image, dtype=np.float32)
        base = ramp[None, :, None, None] + ramp[None, None, :, None] * 0.5 + np.arange(steps + 1)[:, None, None, None]
        rgb = (base + rng.integers(0, 40, (steps + 1, image, image, 3))).astype(np.uint8)
        out.append(dict(observations={"rgb": rgb, "state": rng.standard_normal((steps + 1, 8), np.float32)},
                        actions=rng.standard_normal((steps, 4), np.float32),
                        rewards=rng.standard_normal(steps).astype(np.float32),
                        terminated=np.arange(steps) == steps - 1, episode=k))
    return out


def trajectory_bytes(t: dict) -> int:
    return (sum(v.nbytes for v in t["observations"].values()) + t["actions"].nbytes + t["rewards"].nbytes
            + 2 * t["terminated"].nbytes)


def evict(path: str) -> None:
    """Drops ``path``'s files from the page cache (they are synced first), so reads come from disk."""
    os.sync()
    for directory, _, files in os.walk(path):
        for name in files:
            fd = os.open(os.path.join(directory, name), os.O_RDONLY)
            try:
                os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
            finally:
                os.close(fd)


def plain_write(directory: str, total: int) -> dict:
    path = os.path.join(directory, "plain.bin")
    block = np.random.default_rng(0).integers(0, 256, 1 << 20, dtype=np.uint8).tobytes()
    start = time.perf_counter()
    with open(path, "wb") as f:
        for _ in range(max(total // len(block), 1)):
            f.write(block)
        buffered = time.perf_counter() - start
        f.flush()
        os.fsync(f.fileno())
    synced = time.perf_counter() - start
    written = max(total // len(block), 1) * len(block)
    os.remove(path)
    return {"name": "plain sequential write", "MB": written / MB, "MB_per_s": written / MB / synced,
            "buffered_MB_per_s": written / MB / buffered}


def write_dataset(path: str, trajectories: list[dict], count: int, group: int, chunk_bytes: int,
                  compression: str | None, image: int) -> dict:
    shutil.rmtree(path, ignore_errors=True)
    obs = {"rgb": {"shape": (image, image, 3), "dtype": "uint8", "compression": compression},
           "state": {"shape": (8,)}}
    ds = jarena.TrajectoryDataset(path, "w", obs_config=obs, act_config={"action": {"shape": (4,)}},
                                  chunk_bytes=chunk_bytes)
    total = 0
    start = time.perf_counter()
    for i in range(0, count, group):
        batch = [trajectories[(i + j) % len(trajectories)] for j in range(min(group, count - i))]
        ds.add_trajectories(batch)
        total += sum(map(trajectory_bytes, batch))
    buffered = time.perf_counter() - start
    os.sync()
    synced = time.perf_counter() - start
    ds.close()
    disk = sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(path) for f in fs)
    return {"name": f"dataset write, {'1 commit per trajectory' if group == 1 else f'1 commit per {group}'}, "
                    f"{chunk_bytes >> 10} KiB chunks, {compression or 'raw'}",
            "MB": total / MB, "MB_per_s": total / MB / synced, "buffered_MB_per_s": total / MB / buffered,
            "disk_MB": disk / MB}


def read_dataset(path: str, key: jax.Array) -> list[dict]:
    rows = []
    ds = jarena.TrajectoryDataset(path)
    for warm in (False, True):
        if not warm:
            evict(path)
        start = time.perf_counter()
        total = sum(sum(v.nbytes for v in t["observation"].values()) + sum(v.nbytes for v in t["action"].values())
                    + t["reward"].nbytes + t["terminated"].nbytes + t["truncated"].nbytes for t in ds)
        seconds = time.perf_counter() - start
        rows.append({"name": f"get_trajectory over all ({'warm' if warm else 'cold'})", "MB": total / MB,
                     "MB_per_s": total / MB / seconds})
    evict(path)
    start = time.perf_counter()
    loader = ds.loader(256, mode="window", length=8, memory_budget=1 << 40)
    jax.block_until_ready(loader._device)
    seconds = time.perf_counter() - start
    rows.append({"name": "loader: whole dataset into memory (cold)", "MB": loader.nbytes / MB,
                 "MB_per_s": loader.nbytes / MB / seconds})
    for warm in (False, True):
        if not warm:
            evict(path)
        stream = ds.loader(256, mode="window", length=8, memory_budget=64 << 20)
        start = time.perf_counter()
        total = 0
        for batch in stream.batches(key, 20):
            total += sum(x.nbytes for x in jax.tree_util.tree_leaves(batch))
        seconds = time.perf_counter() - start
        rows.append({"name": f"streaming loader, 20 batches of 256 windows of 8 (64 MB cache, "
                             f"{'warm' if warm else 'cold'})", "MB": total / MB, "MB_per_s": total / MB / seconds})
    return rows


VARIANTS = ((1, 1 << 22, None), (16, 1 << 22, None), (1, 1 << 20, None), (16, 1 << 20, None),
            (16, 1 << 22, "zstd"))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dir", default="/tmp/jarena_dataset_bench")
    parser.add_argument("--trajectories", type=int, default=200)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--image", type=int, default=64)
    parser.add_argument("--rounds", type=int, default=3, help="rounds of all writes, interleaved (medians kept)")
    parser.add_argument("--out", default=None, help="write the results as JSON here")
    args = parser.parse_args(argv)
    os.makedirs(args.dir, exist_ok=True)
    trajectories = make_trajectories(8, args.steps, args.image)
    total = args.trajectories * trajectory_bytes(trajectories[0])
    path = os.path.join(args.dir, "dataset")
    rounds: dict[str, list[dict]] = {}
    for r in range(args.rounds):
        plain = plain_write(args.dir, total)
        rounds.setdefault(plain["name"], []).append(plain)
        for group, chunk_bytes, compression in VARIANTS:
            row = write_dataset(path, trajectories, args.trajectories, group, chunk_bytes, compression, args.image)
            row["over_plain_same_round"] = row["MB_per_s"] / plain["MB_per_s"]
            rounds.setdefault(row["name"], []).append(row)
            print(r, json.dumps(row), flush=True)
    results = []
    for name, rows in rounds.items():
        summary = {"name": name, "rounds": len(rows)}
        for k in rows[0]:
            if k != "name":
                summary[k] = float(np.median([row[k] for row in rows]))
        summary["MB_per_s_all"] = [round(row["MB_per_s"]) for row in rows]
        results.append(summary)
        print(json.dumps(summary), flush=True)
    write_dataset(path, trajectories, args.trajectories, 16, 1 << 22, None, args.image)
    for row in read_dataset(path, jax.random.key(0)):
        results.append(row)
        print(json.dumps(row), flush=True)
    shutil.rmtree(path, ignore_errors=True)
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"args": vars(args), "results": results}, f, indent=1)


if __name__ == "__main__":
    main()
