"""Learning curve of a world-model run directory against DreamerV3's published points, by environment steps and
by minutes of the run (compilation included): training-episode returns, validations and the final evaluation.
An arena with an action repeat (``action:repeat(N)``) counts decisions in its csv files; they are plotted as N
environment steps each, as DreamerV3 counts them.

    python benchmarks/plot_world_model_run.py benchmarks/world_model_runs/dreamer-walker-walk-100k --task walker-walk

Several run directories (seeds of one config, or the ``seed_<s>`` folders of a ``jarena train --seeds N`` run) are
drawn on the same axes, one colour each (a ``--seeds N`` run directory stands for its seed folders); a run cut
before its final evaluation shows what it logged.
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


def load(run_dir: Path) -> dict:
    """A run directory's curves: training episodes, validations, the final evaluation (None for a run that was cut
    before it), the seconds at each chunk, its config and the environment steps per logged step."""
    every = rows(run_dir / "train.csv")
    # a seed of `jarena train --seeds N` (RUN/seed_<s>) shares its run's config.json
    config_path = run_dir / "config.json" if (run_dir / "config.json").exists() else run_dir.parent / "config.json"
    config = json.loads(config_path.read_text())
    repeat = re.search(r"repeat\((\d+)\)", config["arena"])
    final = None
    if (run_dir / "evaluation.json").exists():
        evaluation = json.loads((run_dir / "evaluation.json").read_text())
        final = evaluation["summary"]["return_mean"] if "summary" in evaluation else evaluation["return_mean"]
    return {"train": [r for r in every if r["episode_return"] == r["episode_return"]],
            "validation": rows(run_dir / "validation.csv") if (run_dir / "validation.csv").exists() else [],
            "final": final, "seconds": {r["env_steps"]: r["seconds"] for r in every}, "config": config,
            "per_decision": int(repeat.group(1)) if repeat else 1}


def seed_dirs(run_dir: Path) -> list[Path]:
    """``run_dir`` itself, or the ``seed_<s>`` folders of a ``jarena train --seeds N`` run, in seed order."""
    if (run_dir / "train.csv").exists():
        return [run_dir]
    seeds = sorted(run_dir.glob("seed_*/train.csv"), key=lambda p: int(p.parent.name.removeprefix("seed_")))
    if not seeds:
        raise SystemExit(f"{run_dir}: no train.csv, nor seed_<s>/train.csv folders of a --seeds run")
    return [p.parent for p in seeds]


def label_of(run_dir: Path) -> str:
    return run_dir.name.replace("_", " ") if run_dir.name.startswith("seed_") else run_dir.name


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dirs", type=Path, nargs="+", help="one run directory, or several (seeds) to overlay")
    parser.add_argument("--task", choices=sorted(DREAMERV3), required=True)
    parser.add_argument("--labels", default=None, help="comma-separated names of the runs (default: their folders)")
    parser.add_argument("--out", type=Path, default=None, help="default: RUN_DIR/curve.png (the first run's)")
    args = parser.parse_args()
    run_dirs = [seed for d in args.run_dirs for seed in seed_dirs(d)]
    runs = [load(d) for d in run_dirs]
    labels = args.labels.split(",") if args.labels else [label_of(d) for d in run_dirs]
    if len(labels) != len(runs):
        parser.error(f"--labels names {len(labels)} runs; {len(runs)} run directories were given "
                     f"({', '.join(map(str, run_dirs))})")
    several = len(runs) > 1
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for i, (run, label) in enumerate(zip(runs, labels, strict=True)):
        colour, prefix = f"C{i}", f"{label}: " if several else ""
        seconds, per_decision = run["seconds"], run["per_decision"]
        for ax, x_of in zip(axes, (lambda s: s * per_decision, lambda s: seconds[s] / 60), strict=True):
            ax.plot([x_of(r["env_steps"]) for r in run["train"]], [r["episode_return"] for r in run["train"]],
                    color=colour if several else "C0", alpha=0.45 if several else 1.0, linewidth=1,
                    label=f"{prefix}training episodes")
            ax.plot([x_of(r["env_steps"]) for r in run["validation"]], [r["return_mean"] for r in run["validation"]],
                    "o-", color=colour if several else "C1", label=f"{prefix}validation (20 episodes)")
            if run["final"] is not None:
                ax.plot([x_of(max(seconds))], [run["final"]], "*", markersize=14, color=colour if several else "C3",
                        label=f"{prefix}eval, 100 episodes ({run['final']:.0f})")
    for ax in axes:
        ax.set_ylabel("episode return")
        ax.set_ylim(0, 1000)
        ax.grid(alpha=0.3)
    published = DREAMERV3[args.task]
    axes[0].plot(list(published), list(published.values()), "s--", color="k", label="DreamerV3, published")
    longest = max(max(run["seconds"]) * run["per_decision"] for run in runs)
    axes[0].set_xlabel("environment steps")
    axes[0].set_xlim(0, max(longest, min(published)) * 1.05)
    axes[1].set_xlabel("minutes (compilation included, validations and checkpoints too)")
    axes[0].legend(fontsize=7 if several else 8)
    config = runs[0]["config"]
    fig.suptitle(f"{config['agent']} on {config['arena']} ({config.get('device', '')}, jax {config.get('jax', '')})")
    fig.tight_layout()
    out = args.out or args.run_dirs[0] / "curve.png"
    fig.savefig(out, dpi=90)
    print(out)


if __name__ == "__main__":
    main()
