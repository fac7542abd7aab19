"""The README's main job over seeds: does its quoted figure hold on this machine for every seed?

Runs the README's main command as a user would, in a fresh process per seed,

    jarena train ppo "classic|domain:cartpole" --run-dir DIR --seed S --no-progress --videos 0

and reads each run's ``evaluation.json`` (the evaluated policy's mean return on the 100 eval episodes,
which policy was selected, wall time). ``--isa`` re-runs the seeds with XLA:CPU limited to an older
instruction set (``--xla_cpu_max_isa``): other vector widths round differently, as other CPUs do, so one
machine can check the figure against the rounding of several. Prints a markdown table and a summary
line, and writes them with ``--out``.

    python benchmarks/main_job_seeds.py                      # seeds 0..9, this CPU's full instruction set
    python benchmarks/main_job_seeds.py --isa native,AVX2,SSE4_2 --out main_job.md
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ARENA = "classic|domain:cartpole"
SOLVED = 475.0  # Gymnasium's reward_threshold for CartPole-v1


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def finish(lines: list[str], summary: str, out: str | None) -> None:
    """Prints the summary line and writes the table and it to ``out`` (markdown), if given."""
    lines.append(summary)
    print(summary)
    if out:
        Path(out).write_text("\n".join(lines) + "\n")


def run_seed(seed: int, isa: str, folder: Path) -> dict:
    env = dict(os.environ)
    if isa != "native":
        env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + f" --xla_cpu_max_isa={isa}").strip()
    run_dir = folder / f"{isa}-seed{seed}"
    command = ["jarena", "train", "ppo", ARENA, "--run-dir", str(run_dir), "--seed", str(seed), "--no-progress",
               "--videos", "0"]
    start = time.perf_counter()
    done = subprocess.run(command, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode:
        raise RuntimeError(f"seed {seed} ({isa}) failed:\n{done.stderr[-3000:]}")
    evaluation = json.loads((run_dir / "evaluation.json").read_text())
    return {"isa": isa, "seed": seed, "return": evaluation["summary"]["return_mean"],
            "min_episode": min(e["return"] for e in evaluation["episodes"]), "selected": evaluation["selected"],
            "wall_s": wall}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=10, help="seeds 0 .. N-1")
    parser.add_argument("--isa", default="native",
                        help="comma-separated XLA:CPU instruction sets: native (this CPU's), AVX512, AVX2, SSE4_2")
    parser.add_argument("--out", default=None, help="also write the table to this markdown file")
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error(f"--seeds must be at least 1, got {args.seeds}")
    lines = [f"# README main job, {args.seeds} seeds: `jarena train ppo \"{ARENA}\"`",
             f"CPU: {cpu_model()} ({os.cpu_count()} CPUs), Python {platform.python_version()}",
             "", "| instruction set | seed | eval return (100 episodes) | worst episode | evaluated policy | wall s |",
             "|---|---:|---:|---:|---|---:|"]
    print("\n".join(lines), flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for isa in args.isa.split(","):
            for seed in range(args.seeds):
                row = run_seed(seed, isa.strip(), Path(tmp))
                rows.append(row)
                chosen = row["selected"]
                lines.append(f"| {row['isa']} | {seed} | {row['return']:.1f} | {row['min_episode']:.0f} | "
                             f"{chosen['select']}, step {chosen['env_steps']} | {row['wall_s']:.1f} |")
                print(lines[-1], flush=True)
    returns = [r["return"] for r in rows]
    walls = sorted(r["wall_s"] for r in rows)
    summary = (f"\n{sum(r == 500.0 for r in returns)} of {len(rows)} runs reached 500 on all 100 eval episodes; "
               f"{sum(r >= SOLVED for r in returns)} of {len(rows)} reached {SOLVED:g} (CartPole-v1's solved "
               f"threshold); lowest {min(returns):.1f}; wall {walls[0]:.1f}-{walls[-1]:.1f} s per run "
               "(process start, compile and training included).")
    finish(lines, summary, args.out)


if __name__ == "__main__":
    sys.exit(main())
