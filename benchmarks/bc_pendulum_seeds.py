"""The README's behaviour-cloning example over seeds: oracle demonstrations, then BC, as a user runs them.

Per seed S, in fresh processes:

    jarena collect oracle_pendulum "classic|domain:pendulum,task:swingup" --out DEMOS --trajectories 50 --seed S
    jarena train bc "classic|domain:pendulum,task:swingup" --set dataset=DEMOS --run-dir DIR --seed S --videos 0

and reads the oracle's mean return over the collected trajectories and BC's evaluation (100 eval
episodes) from ``evaluation.json``, with the wall time of each command. Prints a markdown table.

    python benchmarks/bc_pendulum_seeds.py --seeds 5 --out bc.md
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from main_job_seeds import cpu_model, finish

ARENA = "classic|domain:pendulum,task:swingup"


def timed(command: list[str]) -> tuple[str, float]:
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(f"{' '.join(command)} failed:\n{done.stderr[-3000:]}")
    return done.stdout, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=5, help="seeds 0 .. N-1")
    parser.add_argument("--out", default=None, help="also write the table to this markdown file")
    args = parser.parse_args()
    lines = [f"# README behaviour cloning, {args.seeds} seeds: oracle_pendulum demonstrations (50), then bc",
             f"CPU: {cpu_model()} ({os.cpu_count()} CPUs), Python {platform.python_version()}", "",
             "| seed | oracle return (demos) | BC eval return (100 episodes) | collect s | train s |",
             "|---:|---:|---:|---:|---:|"]
    print("\n".join(lines), flush=True)
    returns, walls = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            demos, run_dir = Path(tmp, f"demos{seed}"), Path(tmp, f"bc{seed}")
            out, collect_s = timed(["jarena", "collect", "oracle_pendulum", ARENA, "--out", str(demos),
                                    "--trajectories", "50", "--seed", str(seed), "--no-progress"])
            oracle = float(re.search(r"return (-?[\d.]+) \+-", out).group(1))
            _, train_s = timed(["jarena", "train", "bc", ARENA, "--set", f"dataset={demos}", "--run-dir",
                                str(run_dir), "--seed", str(seed), "--no-progress", "--videos", "0"])
            bc = json.loads((run_dir / "evaluation.json").read_text())["summary"]["return_mean"]
            returns.append(bc)
            walls.append(collect_s + train_s)
            lines.append(f"| {seed} | {oracle:.1f} | {bc:.1f} | {collect_s:.1f} | {train_s:.1f} |")
            print(lines[-1], flush=True)
    summary = (f"\nBC eval return {min(returns):.1f} .. {max(returns):.1f} over {len(returns)} seeds "
               f"(mean {sum(returns) / len(returns):.1f}); collect + train {min(walls):.0f}-{max(walls):.0f} s "
               "(process starts and compiles included).")
    finish(lines, summary, args.out)


if __name__ == "__main__":
    sys.exit(main())
