"""``train_and_evaluate``: train a trainable agent in compiled chunks, validate, evaluate, log.

A trainable agent extends the agent protocol with ``init_training(key, arena) -> train_state``,
``train(train_state, arena, num_updates) -> (train_state, metrics)`` (jittable; metrics have a
leading update axis), ``policy(train_state, spec, deterministic) -> agent_state`` and ``settings``
(its config, with ``steps_per_update`` and ``num_updates``). Host work (progress bar, logs,
validation) happens between compiled chunks, never per step.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import time
import warnings
from pathlib import Path
from typing import Any

import jax
import numpy as np

from jarena.checkpoint import Checkpointer
from jarena.core.arena import Arena
from jarena.render.frames import RenderError
from jarena.runners.evaluate import evaluate, validate
from jarena.runners.results import EvalResult


@dataclasses.dataclass
class TrainResult:
    """train_state: the final training state; history: one dict per chunk; evaluation: on the eval split
    (``None`` when stopped early)."""

    train_state: Any
    history: list[dict[str, float]]
    validations: list[dict[str, float]]
    evaluation: EvalResult | None


def _check_trainable(agent) -> None:
    missing = [n for n in ("init_training", "train", "policy", "settings") if getattr(agent, n, None) is None]
    if missing:
        raise TypeError(f"agent {agent.name!r} is not trainable (missing {missing}); trainable agents: "
                        "build one such as jarena_agents.build_agent('ppo')")


def train_and_evaluate(agent, arena: Arena, key: jax.Array, *, total_steps: int | None = None,
                       chunk_updates: int | None = None, validate_every: int | None = None,
                       checkpoint_every: int | None = None, run_dir: str | Path | None = None,
                       progress: bool = True, stop_after_chunks: int | None = None, eval_videos: int = 2
                       ) -> TrainResult:
    """Trains ``agent`` on ``arena``, validating periodically, and evaluates it on the eval episodes.

    Args:
      agent: a trainable agent (e.g. ``build_agent("ppo", config)``).
      arena: the arena to train on; validation and evaluation use its ``val`` and ``eval`` episodes.
      key: PRNG key; the run is a deterministic function of it.
      total_steps: environment steps to train for (default: the agent config's ``total_steps``).
      chunk_updates: updates per compiled chunk (default: about 20 chunks per run).
      validate_every: validate every this many chunks (default: 5; 0 disables).
      checkpoint_every: with ``run_dir``, checkpoint every this many chunks (default: 5) under
        ``run_dir/checkpoints``; a run restarted in the same directory resumes from the latest one and
        continues bit for bit.
      run_dir: if given, writes ``config.json``, ``train.csv``, ``validation.csv``, TensorBoard event
        files (``tensorboard/``), ``evaluation.json``, ``learning_curve.png`` and videos there.
      progress: show a progress bar with steps per second, current return and ETA.
      stop_after_chunks: stop (without evaluating) after this many chunks in this call, as an
        interruption would; returns ``evaluation=None``. For tests and time-sliced jobs.
      eval_videos: with ``run_dir``, film the first this many eval episodes of the final evaluation into
        ``run_dir/videos/eval_episode_<i>.mp4`` (320 x 240, real time, at most 50 fps). The evaluation keeps
        their physics states on device and renders them on the host afterwards; its results are the
        same as without. Skipped (silently) when the arena's dynamics have no renderer; 0 disables.
    """
    _check_trainable(agent)
    settings = agent.settings
    steps_per_update = settings.steps_per_update
    total_steps = total_steps or settings.total_steps
    num_updates = max(1, math.ceil(total_steps / steps_per_update))
    chunk_updates = chunk_updates or max(1, math.ceil(num_updates / 20))
    num_chunks = math.ceil(num_updates / chunk_updates)
    num_updates = num_chunks * chunk_updates  # equal chunks: one compilation (may add < 1 chunk of steps)
    validate_every = 5 if validate_every is None else validate_every
    run_path = Path(run_dir) if run_dir is not None else None
    if run_path is not None:
        run_path.mkdir(parents=True, exist_ok=True)
        (run_path / "config.json").write_text(json.dumps(
            {"agent": agent.name, "arena": arena.build_string or arena.name, "config": agent.config,
             "total_steps": total_steps, "jax": jax.__version__, "device": str(jax.devices()[0])},
            indent=2, default=str))

    train_state = jax.jit(agent.init_training, static_argnums=1)(key, arena)
    chunk = jax.jit(agent.train, static_argnums=(1, 2), donate_argnums=0)
    history, validations = [], []
    checkpoint_every = 5 if checkpoint_every is None else checkpoint_every
    checkpointer = Checkpointer(run_path / "checkpoints") if run_path is not None and checkpoint_every else None
    first_chunk = 0
    if checkpointer is not None and checkpointer.latest_step() is not None:
        first_chunk = checkpointer.latest_step()
        train_state, meta = checkpointer.restore(train_state, first_chunk)
        history, validations = meta.get("history", []), meta.get("validations", [])
    writer = _TensorBoard(run_path / "tensorboard") if run_path is not None else None
    bar = _progress(num_updates * steps_per_update, progress)
    bar.update(first_chunk * chunk_updates * steps_per_update, history[-1]["episode_return"] if history else 0.0)
    start = time.perf_counter() - (history[-1]["seconds"] if history else 0.0)
    done_updates = first_chunk * chunk_updates
    for ran, index in enumerate(range(first_chunk, num_chunks)):
        if stop_after_chunks is not None and ran >= stop_after_chunks:
            bar.close()
            if checkpointer is not None:
                checkpointer.close()
            if writer is not None:
                writer.close()
            return TrainResult(train_state=train_state, history=history, validations=validations, evaluation=None)
        n = min(chunk_updates, num_updates - done_updates)
        train_state, metrics = chunk(train_state, arena, n)
        metrics = jax.device_get(metrics)
        done_updates += n
        episodes = float(np.sum(metrics["episodes"]))
        weights = np.asarray(metrics["episodes"], np.float64)
        row = {"update": done_updates, "env_steps": done_updates * steps_per_update,
               "seconds": time.perf_counter() - start,
               "episode_return": float(np.sum(np.asarray(metrics["episode_return"]) * weights) / episodes)
               if episodes else float("nan"), "episodes": episodes}
        row.update({k: float(np.mean(v)) for k, v in metrics.items() if k not in ("episodes", "episode_return")})
        history.append(row)
        bar.update(n * steps_per_update, row["episode_return"])
        if writer is not None:
            writer.log("train", row)
        if validate_every and ((index + 1) % validate_every == 0) and index + 1 < num_chunks:
            result = validate(agent, arena, jax.random.key(index),
                              agent_state=agent.policy(train_state, arena.spec, True))
            validations.append({"update": done_updates, "env_steps": row["env_steps"], **result.summary()})
            if writer is not None:
                writer.log("validation", validations[-1])
            bar.note(f"validation return {validations[-1]['return_mean']:.1f}")
        if checkpointer is not None and ((index + 1) % checkpoint_every == 0 or index + 1 == num_chunks):
            checkpointer.save(index + 1, train_state, {"history": history, "validations": validations})
    bar.close()
    if checkpointer is not None:
        checkpointer.close()
    if writer is not None:
        writer.close()
    videos = 0
    if run_path is not None and eval_videos:
        from jarena.render.frames import can_render

        videos = min(int(eval_videos), arena.num_eval_episodes) if can_render(arena) else 0
    policy = agent.policy(train_state, arena.spec, True)
    try:
        evaluation = evaluate(agent, arena, jax.random.key(0), agent_state=policy, videos=videos,
                              video_dir=run_path / "videos" if videos else None)
    except RenderError as e:  # raised before the rollout compiles; the evaluation matters more than videos
        warnings.warn(f"evaluating without videos: {e}", stacklevel=2)
        evaluation = evaluate(agent, arena, jax.random.key(0), agent_state=policy)
    if run_path is not None:
        _write_csv(run_path / "train.csv", history)
        _write_csv(run_path / "validation.csv", validations)
        (run_path / "evaluation.json").write_text(json.dumps(
            {"summary": evaluation.summary(), "episodes": evaluation.per_episode()}, indent=2))
        _plot(run_path / "learning_curve.png", history, validations, evaluation, agent.name, arena.name)
    return TrainResult(train_state=train_state, history=history, validations=validations, evaluation=evaluation)


def _write_csv(path: Path, rows: list[dict[str, float]]) -> None:
    if not rows:
        return
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def _plot(path: Path, history, validations, evaluation, agent: str, arena: str) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # plotting is optional
        return
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot([r["env_steps"] for r in history], [r["episode_return"] for r in history], label="training episodes")
    if validations:
        ax.plot([r["env_steps"] for r in validations], [r["return_mean"] for r in validations], "o-",
                label="validation")
    ax.axhline(evaluation.summary()["return_mean"], color="k", ls="--", label="final evaluation")
    ax.set_xlabel("environment steps")
    ax.set_ylabel("episode return")
    ax.set_title(f"{agent} on {arena}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


class _TensorBoard:
    """TensorBoard event files: one scalar per metric, indexed by environment steps."""

    def __init__(self, path: Path):
        from tensorboardX import SummaryWriter

        self.writer = SummaryWriter(str(path))

    def log(self, group: str, row: dict[str, float]) -> None:
        for name, value in row.items():
            if name not in ("env_steps", "update") and np.isfinite(value):
                self.writer.add_scalar(f"{group}/{name}", value, global_step=int(row["env_steps"]))

    def close(self) -> None:
        self.writer.close()


class _progress:
    """A tqdm bar over environment steps showing steps/s, the latest return and ETA (or nothing)."""

    def __init__(self, total: int, enabled: bool):
        self.bar = None
        if enabled:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=total, unit="step", unit_scale=True, dynamic_ncols=True, desc="training")

    def update(self, steps: int, episode_return: float) -> None:
        if self.bar is not None:
            self.bar.set_postfix(ret=f"{episode_return:.1f}", refresh=False)
            self.bar.update(steps)

    def note(self, text: str) -> None:
        if self.bar is not None:
            self.bar.write(text)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
