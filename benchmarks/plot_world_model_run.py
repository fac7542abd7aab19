"""Learning curve of a world-model run directory against DreamerV3's published points, by environment steps and
by minutes of the run (compilation included): training-episode returns, validations and the final evaluation.
An arena with an action repeat (``action:repeat(N)``) counts decisions in its csv files; they are plotted as N
environment steps each, as DreamerV3 counts them.

    python benchmarks/plot_world_model_run.py benchmarks/world_model_runs/dreamer-walker-walk-100k --task walker-walk
"""

from __future__ import annotations

import argparse
import csv
import json
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

# DreamerV3's published scores: mean over its seeds near each step count (danijar/dreamerv3, scores/).
DREAMERV3 = {"walker-walk": {100_000: 518, 500_000: 925}, "cartpole-swingup": {100_000: 513, 500_000: 853},
             "walker-walk-pixels": {100_000: 639, 500_000: 944, 1_000_000: 962},
             "cartpole-swingup-pixels": {100_000: 615, 500_000: 845, 1_000_000: 862},
             "cheetah-run-pixels": {100_000: 337, 500_000: 663, 1_000_000: 823}}


def rows(path: Path) -> list[dict[str, float]]:
    with open(path) as f:
        return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--task", choices=sorted(DREAMERV3), required=True)
    parser.add_argument("--out", type=Path, default=None, help="default: RUN_DIR/curve.png")
    args = parser.parse_args()
    train = [r for r in rows(args.run_dir / "train.csv") if r["episode_return"] == r["episode_return"]]
    validation = rows(args.run_dir / "validation.csv")
    evaluation = json.loads((args.run_dir / "evaluation.json").read_text())
    seconds = {r["env_steps"]: r["seconds"] for r in rows(args.run_dir / "train.csv")}
    config = json.loads((args.run_dir / "config.json").read_text())
    repeat = re.search(r"repeat\((\d+)\)", config["arena"])
    per_decision = int(repeat.group(1)) if repeat else 1
    final = evaluation["summary"]["return_mean"] if "summary" in evaluation else evaluation["return_mean"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, x_of in zip(axes, (lambda s: s * per_decision, lambda s: seconds[s] / 60), strict=True):
        ax.plot([x_of(r["env_steps"]) for r in train], [r["episode_return"] for r in train], label="training episodes")
        ax.plot([x_of(r["env_steps"]) for r in validation], [r["return_mean"] for r in validation], "o-",
                label="validation (20 episodes)")
        last = max(seconds)
        ax.plot([x_of(last)], [final], "*", markersize=14, color="C3", label=f"eval, 100 episodes ({final:.0f})")
        ax.set_ylabel("episode return")
        ax.set_ylim(0, 1000)
        ax.grid(alpha=0.3)
    published = DREAMERV3[args.task]
    axes[0].plot(list(published), list(published.values()), "s--", color="k", label="DreamerV3, published")
    axes[0].set_xlabel("environment steps")
    axes[0].set_xlim(0, max(max(seconds) * per_decision, min(published)) * 1.05)
    axes[1].set_xlabel("minutes (compilation included, validations and checkpoints too)")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{config['agent']} on {config['arena']} ({config.get('device', '')}, jax {config.get('jax', '')})")
    fig.tight_layout()
    out = args.out or args.run_dir / "curve.png"
    fig.savefig(out, dpi=90)
    print(out)


if __name__ == "__main__":
    main()
