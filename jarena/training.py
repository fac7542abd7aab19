"""``train_and_evaluate``: train a trainable agent in compiled chunks, validate, evaluate, log.

A trainable agent extends the agent protocol with ``init_training(key, arena) -> train_state``,
``train(train_state, arena, num_updates) -> (train_state, metrics)`` (jittable; metrics have a
leading update axis), ``policy(train_state, spec, deterministic) -> agent_state`` and ``settings``
(its config, with ``steps_per_update`` and ``num_updates``). Host work (progress bar, logs,
validation) happens between compiled chunks, never per step.

Which policy is evaluated at the end is a rule of :data:`SELECTIONS`: ``best`` (default) keeps the
policy with the best validation return seen (ties: the latest), since RL training can degrade late in a
run on some seeds and machines; ``last`` evaluates the final policy.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

from jarena import distributed, watchdog
from jarena.checkpoint import Checkpointer
from jarena.core.arena import Arena
from jarena.core.types import ArenaState, Info
from jarena.render.frames import RenderError, can_render
from jarena.render.record import check_video, write_episodes
from jarena.runners.evaluate import evaluate_policies, run_episodes, validate
from jarena.runners.results import EvalResult

# Metrics of a chunk's updates that add up (counts) rather than average.
SUMMED_METRICS = ("episodes", "faulted_episodes")
BEST_POLICY_DIR = "best_policy"
VIDEO_FIXES = ("for MP4 videos install an encoder (pip install imageio-ffmpeg); for MuJoCo arenas without a "
               "display set MUJOCO_GL=egl (or osmesa) before importing jarena")


@dataclasses.dataclass(frozen=True)
class Selection:
    """A rule for the policy ``train_and_evaluate`` evaluates.

    Attributes:
      replaces: ``(value, best_so_far) -> bool``: whether a newly validated policy, whose validation has
        ``value`` in column ``metric``, replaces the kept one (``best_so_far`` is ``None`` before the first);
        ``None`` keeps none (the final policy is evaluated).
      description: for messages and ``--help``.
      name: how it is asked for (``best``, ``last``, ``best:<metric>``).
      metric: the validation column compared (``return_mean``; e.g. ``success_rate``, or an arena metric's
        mean such as ``max_coverage_mean``).
    """

    replaces: Callable[[float, float | None], bool] | None
    description: str
    name: str = "best"
    metric: str = "return_mean"


def _at_least_as_good(value: float, best: float | None) -> bool:
    return bool(np.isfinite(value)) and (best is None or value >= best)  # ties: the latest


SELECTIONS: dict[str, Selection] = {
    "best": Selection(_at_least_as_good, "the policy with the best validation return (ties: the latest)"),
    "last": Selection(None, "the policy at the end of training", "last"),
}


def selection(name: str) -> Selection:
    """The :class:`Selection` named ``name``: one of :data:`SELECTIONS`, or ``best:<metric>``, the policy with the
    highest validation ``<metric>`` (a column of ``validation.csv``: ``success_rate``, or ``<name>_mean`` for an
    arena metric, e.g. ``best:max_coverage_mean`` on PushT)."""
    if isinstance(name, str) and name.startswith("best:") and name[5:].isidentifier():
        metric = name[5:]
        return Selection(_at_least_as_good, f"the policy with the best validation {metric} (ties: the latest)",
                         name, metric)
    if name not in SELECTIONS:
        raise ValueError(f"unknown select {name!r}; choose from "
                         + ", ".join(f"{k} ({v.description})" for k, v in SELECTIONS.items())
                         + ", or best:<metric> (the best validation value of a validation.csv column, e.g. "
                           "best:success_rate)")
    return SELECTIONS[name]


@dataclasses.dataclass
class TrainResult:
    """train_state: the final training state; history: one dict per chunk; validations: one dict per
    validation; evaluation: on the eval split (``None`` when stopped early); policy: the agent state that
    was evaluated (the selected policy); selected: which one it is (``select``, ``update``, ``env_steps``,
    ``validation_return``)."""

    train_state: Any
    history: list[dict[str, float]]
    validations: list[dict[str, float]]
    evaluation: EvalResult | None
    policy: Any = None
    selected: dict | None = None


def _is_episode(x) -> bool:
    return isinstance(x, ArenaState | Info)


def fresh_episodes(restored, fresh):
    """``restored`` (a train state from a checkpoint) with each of its arena states and infos (every
    ``ArenaState`` and ``Info`` in it) taken from ``fresh``, a train state of the same structure made in this
    process: what a resumed run on a host arena steps from, since a host arena's state is a handle on its
    process's simulators. Everything else (parameters, optimiser, buffers, counters) stays restored."""
    return jax.tree_util.tree_map(lambda old, new: new if _is_episode(old) else old, restored, fresh,
                                  is_leaf=_is_episode)


def _check_trainable(agent) -> None:
    missing = [n for n in ("init_training", "train", "policy", "settings") if getattr(agent, n, None) is None]
    if missing:
        raise TypeError(f"agent {agent.name!r} is not trainable (missing {missing}); trainable agents: "
                        "build one such as jarena_agents.build_agent('ppo')")


def _positive_or_none(name: str, value) -> None:
    if value is not None and (not isinstance(value, int | np.integer) or value < 1):
        raise ValueError(f"train_and_evaluate: {name} must be a positive integer or None, got {value!r}")


def _counts_or_none(name: str, value) -> None:
    if value is not None and (not isinstance(value, int | np.integer) or value < 0):
        raise ValueError(f"train_and_evaluate: {name} must be an integer >= 0 (0 disables) or None, got {value!r}")


def train_and_evaluate(agent, arena: Arena, key: jax.Array, *, total_steps: int | None = None,
                       chunk_updates: int | None = None, validate_every: int | None = None,
                       validations: int = 10, select: str = "best", checkpoint_every: int | None = None,
                       run_dir: str | Path | None = None, progress: bool = True,
                       stop_after_chunks: int | None = None, eval_videos: int = 2,
                       devices: int | str | None = None, eval_arena: Arena | None = None) -> TrainResult:
    """Trains ``agent`` on ``arena``, validating periodically, and evaluates the selected policy on the eval
    episodes.

    Args:
      agent: a trainable agent (e.g. ``build_agent("ppo", config)``).
      arena: the arena to train on; validation and evaluation use its ``val`` and ``eval`` episodes.
      key: PRNG key; the run is a deterministic function of it.
      total_steps: environment steps to train for (default: the agent config's ``total_steps``).
      chunk_updates: updates per compiled chunk (default: about 20 chunks per run).
      validate_every: validate every this many chunks and after the last one (default: so that a run
        validates ``validations`` times; 0 disables validation).
      validations: how many times (at most) a run validates when ``validate_every`` is not given (default 10).
      select: which policy the final evaluation runs (:data:`SELECTIONS`): ``best`` (default), the policy
        with the best validation return (ties: the latest; the final one when nothing was validated),
        ``best:<metric>``, the best by another validation column (e.g. ``best:success_rate``), or ``last``. The
        choice is reported in ``evaluation.selected``, the results table, ``evaluation.json``
        and the plot.
      checkpoint_every: with ``run_dir``, checkpoint every this many chunks (default: 5) under
        ``run_dir/checkpoints``; a run restarted in the same directory resumes from the latest one (saying
        so) and continues bit for bit. The best validated policy is kept in ``run_dir/best_policy``.
      run_dir: if given, writes ``config.json``, ``train.csv``, ``validation.csv``, TensorBoard event
        files (``tensorboard/``), ``evaluation.json``, ``learning_curve.png`` and videos there.
      progress: show a progress bar with steps per second, current return and ETA, and validation returns.
      stop_after_chunks: stop (without evaluating) after this many chunks in this call, as an
        interruption would; returns ``evaluation=None``. For tests and time-sliced jobs.
      eval_videos: with ``run_dir``, film the first this many eval episodes of the final evaluation into
        ``run_dir/videos/eval_episode_<i>.mp4`` (320 x 240, real time, at most 50 fps). The evaluation keeps
        their physics states on device and renders them on the host afterwards, once the results are
        written; an arena without a renderer is filmed not at all, and a renderer or encoder that fails
        is a warning naming the fix, never a lost result. 0 disables.
      devices: train data-parallel on a mesh of this many devices (:func:`jarena.distributed.mesh`):
        ``"all"``, a count, or ``None`` (all devices of a multi-process run, else one). The arena batch
        is split over them and the rest replicated; the run computes what it computes on one device (up to
        the order of float sums). In a multi-process run (:func:`jarena.distributed.initialize`) every
        process calls this alike; only process 0 writes to ``run_dir`` and shows progress, and checkpoints
        are written and restored by all.
      eval_arena: validate and evaluate on this arena's ``val`` and ``eval`` episodes instead of ``arena``'s:
        train on cheaper physics (e.g. the Control Suite with fewer solver iterations) and report the return on
        the reference physics. Its observation and action specs must be ``arena``'s (else a ``ValueError``).
    """
    _check_trainable(agent)
    eval_arena = arena if eval_arena is None else eval_arena
    _check_same_specs(arena, eval_arena)
    rule = selection(select)
    for name, value in (("total_steps", total_steps), ("chunk_updates", chunk_updates),
                        ("stop_after_chunks", stop_after_chunks), ("validations", validations)):
        _positive_or_none(name, value)
    for name, value in (("validate_every", validate_every), ("checkpoint_every", checkpoint_every),
                        ("eval_videos", eval_videos)):
        _counts_or_none(name, value)
    steps_per_update = agent.settings.steps_per_update
    total_steps = total_steps or agent.settings.total_steps
    num_chunks, chunk_updates, validate_every = training_schedule(agent.settings, total_steps, chunk_updates,
                                                                  validate_every, validations)
    num_updates = num_chunks * chunk_updates
    mesh = distributed.mesh(devices)
    main = distributed.is_main_process()
    progress = progress and main
    run_path = Path(run_dir) if run_dir is not None else None
    log_path = run_path if main else None  # checkpoints are written by every process, the rest by process 0
    if log_path is not None:
        log_path.mkdir(parents=True, exist_ok=True)
        (log_path / "config.json").write_text(json.dumps(
            _run_config(agent, arena, eval_arena, key=_key_words(key), total_steps=total_steps, select=select,
                        devices=int(mesh.devices.size), processes=jax.process_count()), indent=2, default=str))

    train_state, chunk = _compiled_training(agent, arena, key, mesh)
    history, validations_done = [], []
    checkpoint_every = 5 if checkpoint_every is None else checkpoint_every
    checkpointer = Checkpointer(run_path / "checkpoints") if run_path is not None and checkpoint_every else None
    watchdog.set_resume_hint(
        f"start every process again with the same command: the run resumes from its last checkpoint in "
        f"{checkpointer.directory}" if checkpointer is not None else
        "start the run again (it has no checkpoints: give it a run directory to keep them)")
    keeper = _BestPolicy(agent, eval_arena, rule, run_path / BEST_POLICY_DIR if checkpointer is not None else None)
    first_chunk = 0
    if checkpointer is not None and checkpointer.latest_step() is not None:
        first_chunk = checkpointer.latest_step()
        _check_same_kind(checkpointer, first_chunk, run_path, None)
        restored, meta = checkpointer.restore(train_state, first_chunk)
        if arena.dynamics.on_host:  # a checkpoint holds handles on the last process's simulators, not their state
            restored = fresh_episodes(restored, train_state)
            _say(main, "host arena: the resumed run starts new episodes (a simulator's state is not checkpointed)")
        train_state = restored
        history, validations_done = meta.get("history", []), meta.get("validations", [])
        keeper.resume(train_state, first_chunk)
        _say(main, f"resuming from step {first_chunk * chunk_updates * steps_per_update} of "
              f"{num_updates * steps_per_update} (checkpoint {checkpointer.directory / str(first_chunk)})")
    writer = _TensorBoard(log_path / "tensorboard") if log_path is not None else None
    bar = _progress(num_updates * steps_per_update, progress)
    bar.update(first_chunk * chunk_updates * steps_per_update, history[-1] if history else {})
    start = time.perf_counter() - (history[-1]["seconds"] if history else 0.0)
    done_updates = first_chunk * chunk_updates

    def close():
        bar.close()
        for closing in (checkpointer, writer, keeper):
            if closing is not None:
                closing.close()

    try:  # whatever ends the loop (an error, SIGTERM), the logs and checkpoint managers are closed
        for ran, index in enumerate(range(first_chunk, num_chunks)):
            if stop_after_chunks is not None and ran >= stop_after_chunks:
                return TrainResult(train_state=train_state, history=history, validations=validations_done,
                                   evaluation=None)
            n = min(chunk_updates, num_updates - done_updates)
            with distributed.tracing_on(mesh):
                train_state, metrics = chunk(train_state, arena, n)
            metrics = distributed.fetch(metrics, f"training chunk {index + 1}")
            done_updates += n
            row = _history_row(metrics, done_updates, steps_per_update, time.perf_counter() - start)
            history.append(row)
            bar.update(n * steps_per_update, row)
            if writer is not None:
                writer.log("train", row)
            if validate_every and ((index + 1) % validate_every == 0 or index + 1 == num_chunks):
                result = validate(agent, eval_arena, jax.random.key(index),
                                  agent_state=_local_policy(agent.policy(train_state, arena.spec, True), mesh),
                                  devices=devices)
                validations_done.append({"update": done_updates, "env_steps": row["env_steps"], **result.summary()})
                if writer is not None:
                    writer.log("validation", validations_done[-1])
                kept = keeper.offer(train_state, index + 1, validations_done[-1])
                bar.note(f"validation return {validations_done[-1]['return_mean']:.1f} at step {row['env_steps']}"
                         + (" (best so far: kept)" if kept else ""))
            if log_path is not None:  # the curves so far survive a run that is stopped or killed
                _write_csv(log_path / "train.csv", history)
                _write_csv(log_path / "validation.csv", validations_done)
            if checkpointer is not None and ((index + 1) % checkpoint_every == 0 or index + 1 == num_chunks):
                distributed.collective_point(f"checkpoint {index + 1}")
                checkpointer.save(index + 1, train_state, {"history": history, "validations": validations_done})
    finally:
        close()
    policy, selected = keeper.choice(train_state, history[-1] if history else None,
                                     validations_done[-1] if validations_done else None)
    evaluation = _evaluate_and_write(agent, eval_arena, _local_policy(policy, mesh), selected, run_path, log_path,
                                     eval_videos, history, validations_done, devices)
    return TrainResult(train_state=train_state, history=history, validations=validations_done,
                       evaluation=evaluation, policy=policy, selected=selected)


@dataclasses.dataclass(frozen=True)
class SeedsResult:
    """What :func:`train_seeds` returns: ``train_state`` (leaves with a leading seed axis (S, ...)), ``histories``
    (per seed, one dict per chunk, as :attr:`TrainResult.history`), ``evaluations`` (per seed, its final policy on
    the eval episodes), the ``seeds``, in that order, and ``validations`` (per seed, one dict per validation, as
    :attr:`TrainResult.validations`; empty lists when the run did not validate)."""

    train_state: Any
    histories: list[list[dict[str, float]]]
    evaluations: list[EvalResult]
    seeds: list[int]
    validations: list[list[dict[str, float]]] = dataclasses.field(default_factory=list)

    def summary(self) -> dict[str, float]:
        """Over the seeds: ``seeds``, and the mean and standard deviation (ddof 0) of each seed's evaluation
        summary value (``return_mean_mean``, ``return_mean_std``, ``success_rate_mean``, ...)."""
        rows = [e.summary() for e in self.evaluations]
        out = {"seeds": float(len(rows))}
        for name in rows[0]:
            values = np.asarray([r[name] for r in rows], np.float64)
            out[f"{name}_mean"], out[f"{name}_std"] = float(values.mean()), float(values.std())
        return out

    def table(self) -> str:
        """One line per seed (eval return mean +- std over its episodes, success) and the mean over seeds."""
        lines = ["seed | eval return (mean +- std over episodes) | success | evaluated policy"]
        for seed, evaluation in zip(self.seeds, self.evaluations, strict=True):
            s, chosen = evaluation.summary(), evaluation.selected or {}
            lines.append(f"{seed} | {s['return_mean']:.1f} +- {s['return_std']:.1f} | {s.get('success_rate', 0):.0%} | "
                         f"{chosen.get('select', 'last')}, step {chosen.get('env_steps', '?')}")
        total = self.summary()
        lines.append(f"all {len(self.seeds)} | {total['return_mean_mean']:.1f} +- {total['return_mean_std']:.1f} "
                     f"(over seeds) | {total.get('success_rate_mean', 0):.0%}")
        return "\n".join(lines)


def train_seeds(agent, arena: Arena, seeds, *, total_steps: int | None = None, chunk_updates: int | None = None,
                validate_every: int | None = None, validations: int = 0, select: str = "best",
                checkpoint_every: int | None = None, run_dir: str | Path | None = None, progress: bool = True,
                stop_after_chunks: int | None = None, eval_arena: Arena | None = None) -> SeedsResult:
    """Trains ``agent`` once per seed, all seeds in one compiled program (the agent's training vmapped over a
    leading seed axis), validating all seeds at once as it goes, then evaluates each seed's final policy on the
    eval episodes (all seeds in one batch: :func:`jarena.runners.evaluate.evaluate_policies`), each seed's policy
    chosen by ``select`` as :func:`train_and_evaluate` chooses.

    Meant for runs that leave the device idle (a world model's gradient step on a batch of 16 sequences, a
    collection step of a few arenas), where S seeds should cost little more than one. Seed ``s``'s run is the run
    :func:`train_and_evaluate` makes with ``jax.random.key(s)`` (the same updates, validations and selection;
    batched operations may round differently). With a run directory the run checkpoints, as
    :func:`train_and_evaluate` does, and a call with the same directory and seeds resumes it. Each seed holds its
    own training state (replay buffer, or a dataset agent's copy of its data): memory grows with the seeds.

    Args:
      agent: a trainable agent.
      arena: the arena to train on.
      seeds: the seeds (ints), e.g. ``range(3)``; each seed's key is ``jax.random.key(seed)``.
      total_steps: environment steps to train each seed for (default: the agent config's ``total_steps``).
      chunk_updates: updates per compiled chunk (default: about 20 chunks per run).
      validate_every: validate every this many chunks and after the last (0: never); by default so that the run
        validates ``validations`` times (default 0: it does not validate), as :func:`train_and_evaluate`.
      validations: how many times (at most) the run validates when ``validate_every`` is not given.
      select: which policy of each seed the final evaluation runs (:func:`train_and_evaluate`'s ``select``);
        without validations, the last.
      checkpoint_every: with ``run_dir``, checkpoint every this many chunks and after the last (default: 5; 0:
        never) under ``run_dir/checkpoints``: every seed's training state and the policies kept so far. A call
        with the same ``run_dir`` resumes from the latest checkpoint (saying so) and continues bit for bit; one
        with other seeds is a ``ValueError``.
      run_dir: if given, writes ``config.json``, ``seed_<s>/train.csv``, ``seed_<s>/validation.csv``,
        ``seed_<s>/evaluation.json`` and ``seed_<s>/learning_curve.png`` per seed, and ``seeds.csv`` (one row per
        seed: its evaluation summary).
      progress: a progress bar over the environment steps of one seed.
      stop_after_chunks: stop (without evaluating) after this many chunks in this call, as an interruption would;
        ``evaluations`` is then empty. For tests and time-sliced jobs.
      eval_arena: validate and evaluate on this arena instead (the same specs), as :func:`train_and_evaluate`'s.
    """
    _check_trainable(agent)
    seeds = [int(s) for s in seeds]
    if not seeds or len(set(seeds)) != len(seeds):
        raise ValueError(f"train_seeds needs one or more distinct seeds, got {seeds}")
    for name, value in (("total_steps", total_steps), ("chunk_updates", chunk_updates),
                        ("stop_after_chunks", stop_after_chunks)):
        _positive_or_none(name, value)
    _counts_or_none("validate_every", validate_every)
    _counts_or_none("checkpoint_every", checkpoint_every)
    if isinstance(validations, bool) or not isinstance(validations, int) or validations < 0:
        raise ValueError(f"validations must be a whole number >= 0 (0: never), got {validations!r}")
    rule = selection(select)
    eval_arena = arena if eval_arena is None else eval_arena
    _check_same_specs(arena, eval_arena)
    steps_per_update = agent.settings.steps_per_update
    total_steps = total_steps or agent.settings.total_steps
    num_chunks, chunk_updates, validate_every = training_schedule(agent.settings, total_steps, chunk_updates,
                                                                  validate_every, validations)
    num_updates = num_chunks * chunk_updates
    run_path = Path(run_dir) if run_dir is not None else None
    if run_path is not None:
        run_path.mkdir(parents=True, exist_ok=True)
        for seed in seeds:
            (run_path / f"seed_{seed}").mkdir(exist_ok=True)
        (run_path / "config.json").write_text(json.dumps(
            _run_config(agent, arena, eval_arena, total_steps=total_steps, seeds=seeds, select=select), indent=2,
            default=str))
    train_state = _init_seeds(agent, arena, seeds)
    chunk = jax.jit(lambda ts, n: jax.vmap(lambda one: agent.train(one, arena, n))(ts), static_argnums=1,
                    donate_argnums=0)
    policies = _stacked_policies(agent, eval_arena.spec)
    histories: list[list[dict[str, float]]] = [[] for _ in seeds]
    validated: list[list[dict[str, float]]] = [[] for _ in seeds]
    kept: list[tuple[Any, dict] | None] = [None for _ in seeds]  # per seed: (host copy of its policy, its row)
    checkpoint_every = 5 if checkpoint_every is None else checkpoint_every
    checkpointer = Checkpointer(run_path / "checkpoints") if run_path is not None and checkpoint_every else None
    first_chunk = 0
    if checkpointer is not None and checkpointer.latest_step() is not None:
        first_chunk = checkpointer.latest_step()
        _check_same_kind(checkpointer, first_chunk, run_path, seeds)
        template = {"train": train_state, "kept": policies(train_state)}
        restored, meta = checkpointer.restore(template, first_chunk)
        train_state, histories, validated = restored["train"], meta["histories"], meta["validations"]
        kept_policies = jax.device_get(restored["kept"])
        kept = [None if row is None else (_seed_slice(kept_policies, i), row)
                for i, row in enumerate(meta["kept_rows"])]
        _say(True, f"resuming from step {first_chunk * chunk_updates * steps_per_update} of "
                   f"{num_updates * steps_per_update} (checkpoint {checkpointer.directory / str(first_chunk)})")
    bar = _progress(num_updates * steps_per_update, progress)
    bar.update(first_chunk * chunk_updates * steps_per_update, _mean_row([h[-1] for h in histories]) if first_chunk
               else {})
    done = first_chunk * chunk_updates
    start = time.perf_counter() - (histories[0][-1]["seconds"] if first_chunk else 0.0)

    def kept_or_current() -> Any:
        """Each seed's kept policy, or its current one where none was kept: host copies stacked (S, ...)."""
        current = jax.device_get(policies(train_state)) if not all(kept) else None
        return jax.tree_util.tree_map(lambda *xs: np.stack(xs), *[
            k[0] if k is not None else _seed_slice(current, i) for i, k in enumerate(kept)])

    def save(chunks: int) -> None:
        checkpointer.save(chunks, {"train": train_state, "kept": kept_or_current()},
                          {"seeds": seeds, "histories": histories, "validations": validated,
                           "kept_rows": [None if k is None else k[1] for k in kept]})

    try:
        for ran, index in enumerate(range(first_chunk, num_chunks)):
            if stop_after_chunks is not None and ran >= stop_after_chunks:
                return SeedsResult(train_state=train_state, histories=histories, evaluations=[], seeds=seeds,
                                   validations=validated)
            n = min(chunk_updates, num_updates - done)
            train_state, metrics = chunk(train_state, n)
            metrics = jax.device_get(metrics)
            done += n
            seconds = time.perf_counter() - start
            for i, history in enumerate(histories):
                history.append(_history_row({k: v[i] for k, v in metrics.items()}, done, steps_per_update, seconds))
            bar.update(n * steps_per_update, _mean_row([h[-1] for h in histories]))
            if validate_every and ((index + 1) % validate_every == 0 or index + 1 == num_chunks):
                stacked = policies(train_state)
                results = evaluate_policies(agent, eval_arena, stacked, jax.random.key(index), split="val")
                for i, (rows, result) in enumerate(zip(validated, results, strict=True)):
                    rows.append({"update": done, "env_steps": done * steps_per_update, **result.summary()})
                    if _prefers(rule, rows[-1], None if kept[i] is None else kept[i][1]):
                        kept[i] = (jax.device_get(_seed_slice(stacked, i)), rows[-1])
                mean = float(np.mean([rows[-1]["return_mean"] for rows in validated]))
                bar.note(f"validation return {mean:.1f} at step {done * steps_per_update} (mean over the seeds)")
            if run_path is not None:  # the curves so far survive a run that is stopped or killed
                for seed, history, rows in zip(seeds, histories, validated, strict=True):
                    _write_csv(run_path / f"seed_{seed}" / "train.csv", history)
                    _write_csv(run_path / f"seed_{seed}" / "validation.csv", rows)
            if checkpointer is not None and ((index + 1) % checkpoint_every == 0 or index + 1 == num_chunks):
                save(index + 1)
    finally:
        bar.close()
        if checkpointer is not None:
            checkpointer.close()
    stacked = kept_or_current()
    selected = [_kept_row(rule, k[1]) if k is not None else _last_row(rule, h[-1] if h else None, v[-1] if v else None)
                for k, h, v in zip(kept, histories, validated, strict=True)]
    evaluations = [dataclasses.replace(e, selected=chosen_row) for e, chosen_row in
                   zip(evaluate_policies(agent, eval_arena, stacked, jax.random.key(0)), selected, strict=True)]
    if run_path is not None:
        substeps = int(getattr(eval_arena.tool, "substeps", 1) or 1)
        for seed, history, rows, evaluation in zip(seeds, histories, validated, evaluations, strict=True):
            _write_evaluation(run_path / f"seed_{seed}" / "evaluation.json", evaluation)
            _plot(run_path / f"seed_{seed}" / "learning_curve.png", history, rows, evaluation, agent.name,
                  f"{_label(arena)}, seed {seed}", substeps)
    result = SeedsResult(train_state=train_state, histories=histories, evaluations=evaluations, seeds=seeds,
                         validations=validated)
    if run_path is not None:
        rows = [{"seed": float(seed), **e.summary()} for seed, e in zip(seeds, evaluations, strict=True)]
        _write_csv(run_path / "seeds.csv", rows)
    return result


def _init_seeds(agent, arena: Arena, seeds: list[int]):
    """The training states of ``seeds`` (seed ``s``: ``jax.random.key(s)``), stacked on a leading axis (S, ...)."""
    keys = jax.random.wrap_key_data(np.stack([np.asarray(jax.random.key_data(jax.random.key(s))) for s in seeds]))
    return jax.jit(jax.vmap(lambda key: agent.init_training(key, arena)))(keys)


def _stacked_policies(agent, spec):
    """Jitted: stacked training states (S, ...) to every seed's deterministic acting policy, stacked; only what the
    policies read is computed (no copy of a replay buffer)."""
    return jax.jit(jax.vmap(lambda one: agent.policy(one, spec, True)))


def _seed_slice(tree, index: int):
    """Seed ``index``'s part of a tree stacked over seeds (leaves (S, ...))."""
    return jax.tree_util.tree_map(lambda x: x[index], tree)


def _check_same_kind(checkpointer: Checkpointer, step: int, run_path: Path, seeds: list[int] | None) -> None:
    """Raises ``ValueError`` unless the checkpoint at ``step`` is a run of these ``seeds`` (:func:`train_seeds`),
    or of one seed (``None``: :func:`train_and_evaluate`), before its state is read; closes ``checkpointer`` then."""
    held = checkpointer.metadata(step).get("seeds")
    if held == seeds:
        return
    checkpointer.close()
    if seeds is None:
        raise ValueError(f"{run_path} holds a run of seeds {held} (jarena train --seeds {len(held)}), not of one: "
                         f"resume it as it was started, or give another run directory")
    what = f"a run of seeds {held}" if held is not None else "a run of one seed (no --seeds)"
    raise ValueError(f"{run_path} holds {what}, not of seeds {seeds}: resume it as it was started, or give another "
                     f"run directory")


def _mean_row(rows: list[dict]) -> dict:
    """The progress bar's row for several seeds: each value averaged over the seeds whose value is finite."""
    out = {}
    for name in rows[0]:
        values = np.asarray([r.get(name, np.nan) for r in rows], np.float64)
        out[name] = float(np.mean(values[np.isfinite(values)])) if np.isfinite(values).any() else float("nan")
    return out


def _check_same_specs(arena: Arena, eval_arena: Arena) -> None:
    """Raises ``ValueError`` naming what differs when a policy trained on ``arena`` cannot act in ``eval_arena``."""
    if eval_arena is arena:
        return
    for what in ("observation", "action", "goal_dim"):
        trained, evaluated = getattr(arena.spec, what), getattr(eval_arena.spec, what)
        if trained != evaluated:
            raise ValueError(f"eval_arena {_label(eval_arena)!r} has another {what} spec than "
                             f"the training arena {_label(arena)!r}: {evaluated!r} against "
                             f"{trained!r}; a policy trained on one must be able to act in the other (the same "
                             f"domain and task, other physics options)")


def _label(arena: Arena) -> str:
    """The string an arena was built from, else its name."""
    return arena.build_string or arena.name


def _run_config(agent, arena: Arena, eval_arena: Arena, **extra) -> dict:
    """A run directory's ``config.json``: the agent, the arena (and the eval arena when another), the agent's config,
    ``extra``, and the jax version and device."""
    return {"agent": agent.name, "arena": _label(arena),
            **({"eval_arena": _label(eval_arena)} if eval_arena is not arena else {}),
            "config": agent.config, **extra, "jax": jax.__version__, "device": str(jax.devices()[0])}


def _key_words(key: jax.Array) -> list[int]:
    """The run's key as its raw words (``jax.random.key(seed)``'s are ``[0, seed]``), for ``config.json``."""
    return [int(word) for word in np.asarray(jax.random.key_data(key)).ravel()]


def _write_evaluation(path: Path, evaluation: EvalResult) -> None:
    """``evaluation.json``: the summary, which policy was evaluated (``selected``) and every episode's results."""
    path.write_text(json.dumps({"summary": evaluation.summary(), "selected": evaluation.selected,
                                "episodes": evaluation.per_episode()}, indent=2))


def _compiled_training(agent, arena: Arena, key: jax.Array, mesh):
    """``(train_state, chunk)``: the initial train state laid out on ``mesh`` (arena batch split, the rest
    replicated) and the jitted chunk of updates that keeps that layout (its input donated).

    The key enters as raw key data (a host value, the same in every process) and is re-wrapped inside.
    """
    key_data, impl = np.asarray(jax.random.key_data(key)), jax.random.key_impl(key)

    def init(data):
        return agent.init_training(jax.random.wrap_key_data(data, impl=impl), arena)

    shardings = distributed.batch_shardings(jax.eval_shape(init, key_data), mesh,
                                            getattr(agent.settings, "num_arenas", None))
    with distributed.tracing_on(mesh):  # compiled as the chunks are (the partitioner: jarena.distributed)
        train_state = jax.jit(init, out_shardings=shardings)(key_data)
    chunk = jax.jit(agent.train, static_argnums=(1, 2), donate_argnums=0, in_shardings=(shardings,),
                    out_shardings=(shardings, distributed.replicated(mesh)))
    return train_state, chunk


def _local_policy(policy, mesh):
    """The policy as host arrays when training spans several devices (validation and evaluation take host
    values, the same in every process, as their inputs); as it is on one device."""
    return policy if mesh.devices.size == 1 else distributed.fetch(policy)


def _say(main: bool, text: str) -> None:
    if main:
        print(text, flush=True)


def training_schedule(settings, total_steps: int | None, chunk_updates: int | None, validate_every: int | None,
                      validations: int) -> tuple[int, int, int]:
    """``(num_chunks, chunk_updates, validate_every)`` of a run: equal chunks (one compilation; may add less
    than a chunk of steps), about 20 of them by default, validated every ``validate_every`` chunks and after
    the last (0: never), by default at most ``validations`` times in all (0: never), as evenly as the chunks
    allow."""
    num_updates = max(1, math.ceil((total_steps or settings.total_steps) / settings.steps_per_update))
    chunk_updates = chunk_updates or max(1, math.ceil(num_updates / 20))
    num_chunks = math.ceil(num_updates / chunk_updates)
    if validate_every is None:
        validate_every = math.ceil(num_chunks / validations) if validations else 0
    return num_chunks, chunk_updates, validate_every


def _history_row(metrics: dict, updates: int, steps_per_update: int, seconds: float) -> dict[str, float]:
    """One chunk's row: counts summed, the finished episodes' return weighted by their number, the rest
    averaged over the chunk's updates."""
    weights = np.asarray(metrics["episodes"], np.float64)
    episodes = float(np.sum(weights))
    row = {"update": updates, "env_steps": updates * steps_per_update, "seconds": seconds,
           "episode_return": float(np.sum(np.asarray(metrics["episode_return"]) * weights) / episodes)
           if episodes else float("nan")}
    row.update({k: float(np.sum(metrics[k])) for k in SUMMED_METRICS if k in metrics})
    row.update({k: float(np.mean(v)) for k, v in metrics.items() if k not in SUMMED_METRICS + ("episode_return",)})
    return row


def _kept_row(rule: Selection, row: dict) -> dict:
    """``selected`` for a policy the rule kept at the validation ``row``."""
    selected = {"select": rule.name, "update": int(row["update"]), "env_steps": int(row["env_steps"]),
                "validation_return": float(row["return_mean"])}
    if rule.metric != "return_mean":
        selected[f"validation_{rule.metric}"] = float(row[rule.metric])
    return selected


def _last_row(rule: Selection, last_row: dict | None, last_validation: dict | None) -> dict:
    """``selected`` for the final policy (the rule is ``last``, or it kept nothing)."""
    final_validated = (last_validation is not None and last_row is not None
                       and last_validation["update"] == last_row["update"])
    return {"select": "last" if rule.replaces is None else "last (nothing validated)",
            "update": int(last_row["update"]) if last_row else 0,
            "env_steps": int(last_row["env_steps"]) if last_row else 0,
            "validation_return": float(last_validation["return_mean"]) if final_validated else None}


def _prefers(rule: Selection, row: dict, kept: dict | None) -> bool:
    """Whether ``rule`` keeps the policy validated at ``row`` over the one kept at ``kept`` (None: nothing yet); a
    metric the validation lacks is an error naming its columns."""
    if rule.replaces is None:
        return False
    if rule.metric not in row:
        raise ValueError(f"select {rule.name!r}: the validation has no column {rule.metric!r}; its columns: "
                         f"{', '.join(sorted(row))}")
    return rule.replaces(float(row[rule.metric]), None if kept is None else float(kept[rule.metric]))


class _BestPolicy:
    """Keeps the selected policy as training goes: a host copy (the train state's buffers are donated to
    the next chunk) and, with a run directory, a checkpoint in ``directory`` so a resumed run keeps it."""

    def __init__(self, agent, arena: Arena, rule: Selection, directory: Path | None):
        self.agent, self.arena, self.rule = agent, arena, rule
        self.saver = Checkpointer(directory, max_to_keep=1) if directory is not None and rule.replaces else None
        self.policy, self.row, self.chunk = None, None, None

    def offer(self, train_state, chunk: int, row: dict) -> bool:
        """Keeps the validated policy of ``train_state`` (after ``chunk`` chunks) if the rule prefers it."""
        if not _prefers(self.rule, row, self.row):
            return False
        self.policy = distributed.fetch(self.agent.policy(train_state, self.arena.spec, True), "best policy")
        self.row, self.chunk = row, chunk
        if self.saver is not None:
            self.saver.save(chunk, self.policy, {"validation": row})
        return True

    def resume(self, train_state, chunk: int) -> None:
        """Restores the kept policy of a run resumed at ``chunk`` (one kept later is found again, identically,
        as the run repeats those chunks)."""
        if self.saver is None or self.saver.latest_step() is None or self.saver.latest_step() > chunk:
            return
        template = self.agent.policy(train_state, self.arena.spec, True)
        policy, meta = self.saver.restore(template)
        self.policy, self.row, self.chunk = distributed.fetch(policy), meta["validation"], self.saver.latest_step()

    def choice(self, train_state, last_row: dict | None, last_validation: dict | None):
        """``(policy, selected)``: the kept policy, or the final one when none was kept."""
        if self.policy is not None:
            return self.policy, _kept_row(self.rule, self.row)
        return self.agent.policy(train_state, self.arena.spec, True), _last_row(self.rule, last_row, last_validation)

    def close(self) -> None:
        if self.saver is not None:
            self.saver.close()


def _evaluate_and_write(agent, arena: Arena, policy, selected: dict, run_path: Path | None, log_path: Path | None,
                        eval_videos: int, history, validations, devices=None) -> EvalResult:
    """Evaluates ``policy`` on the eval split and writes the results to ``log_path`` (process 0's run directory);
    videos come last, and a failure in rendering or encoding them is a warning (the results are already on disk).

    How many episodes are filmed depends only on what every process knows alike (a run directory, the arena
    can render): it shapes the compiled evaluation, which all processes must share."""
    videos = min(int(eval_videos), arena.num_eval_episodes) if run_path is not None and can_render(arena) else 0
    write_videos = bool(videos) and log_path is not None
    if write_videos:
        try:
            check_video(arena)  # before compiling: no OpenGL here means no videos, not no results
        except RenderError as e:
            warnings.warn(f"evaluating without videos: {e}", stacklevel=3)
            write_videos = False
    evaluation, physics = run_episodes(agent, arena, jax.random.key(0), agent_state=policy, filmed=videos,
                                       devices=devices)
    evaluation = dataclasses.replace(evaluation, selected=selected)
    # the collective part ends here: process 0 writes the results and renders the videos from host copies
    if log_path is None:
        return evaluation
    _write_csv(log_path / "train.csv", history)
    _write_csv(log_path / "validation.csv", validations)
    _write_evaluation(log_path / "evaluation.json", evaluation)
    _plot(log_path / "learning_curve.png", history, validations, evaluation, agent.name, arena.name,
          int(getattr(arena.tool, "substeps", 1) or 1))
    if write_videos:
        paths = [log_path / "videos" / f"eval_episode_{int(i)}" for i in evaluation.episodes[:videos]]
        try:
            write_episodes(arena, physics, evaluation.lengths[:videos], paths)
        except Exception as e:  # a renderer or encoder failing: the results above are written already
            warnings.warn(f"videos not written ({type(e).__name__}: {e}); the results are in {log_path}. "
                          f"To get videos: {VIDEO_FIXES}", stacklevel=3)
    return evaluation


def _write_csv(path: Path, rows: list[dict[str, float]]) -> None:
    """Writes ``rows`` to ``path`` through a temporary file, so a reader (or a kill) never sees half a file."""
    if not rows:
        return
    partial = path.with_name(path.name + ".partial")
    with open(partial, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    os.replace(partial, path)


def _plot(path: Path, history, validations, evaluation, agent: str, arena: str, substeps: int = 1) -> None:
    """Returns against steps: training episodes, validations, the evaluated policy and its final evaluation; with
    ``select`` ``best:<metric>``, that validation metric and the final evaluation's on a second axis. A run without
    training episodes (an agent learning from a dataset) is plotted against its updates."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # plotting is optional
        return
    fig, ax = plt.subplots(figsize=(6, 4))
    finished = [r for r in history if np.isfinite(r["episode_return"])]  # chunks where no episode ended: no point
    if finished:
        ax.plot([r["env_steps"] for r in finished], [r["episode_return"] for r in finished], label="training episodes")
    if validations:
        ax.plot([r["env_steps"] for r in validations], [r["return_mean"] for r in validations], "o-",
                label="validation")
    selected = evaluation.selected or {}
    if selected.get("validation_return") is not None:
        ax.plot([selected["env_steps"]], [selected["validation_return"]], "*", color="C3", markersize=14,
                label=f"evaluated policy ({selected['select']}, step {selected['env_steps']})")
    summary = evaluation.summary()
    ax.axhline(summary["return_mean"], color="k", ls="--",
               label=f"final evaluation of that policy ({summary['return_mean']:.4g})")
    _show_level(ax, summary["return_mean"])
    handles, labels = ax.get_legend_handles_labels()
    metric = str(selected.get("select", ""))[5:] if str(selected.get("select", "")).startswith("best:") else ""
    if metric and validations and metric in validations[0]:
        twin = ax.twinx()
        twin.plot([r["env_steps"] for r in validations], [r[metric] for r in validations], "s:", color="C2",
                  label=f"validation {metric} (right axis)")
        final = summary.get(metric)
        if final is not None and np.isfinite(final):
            twin.axhline(final, color="C2", ls="--", label=f"final evaluation's {metric} ({final:.4g})")
            _show_level(twin, final)
        twin.set_ylabel(metric)
        extra_handles, extra_labels = twin.get_legend_handles_labels()
        handles, labels = handles + extra_handles, labels + extra_labels
    if not any(r.get("episodes", 0) for r in history):
        ax.set_xlabel("gradient updates")
    else:
        ax.set_xlabel("environment steps" if substeps == 1 else
                      f"decisions (the arena's tool holds each for {substeps} control steps)")
    ax.set_ylabel("episode return")
    title = f"{agent} on {arena}"
    ax.set_title(title, fontsize=12 if len(title) <= 48 else max(7, int(12 * 48 / len(title))))
    ax.legend(handles, labels, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _show_level(ax, level: float) -> None:
    """Widens ``ax``'s y-range so that a horizontal line at ``level`` sits inside it, off the frame."""
    if not np.isfinite(level):
        return
    low, high = ax.get_ylim()
    pad = 0.05 * max(high - low, abs(level) * 0.1, 1e-6)
    ax.set_ylim(min(low, level - pad), max(high, level + pad))


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


def shown_return(row: dict) -> str:
    """The progress bar's return for a history row: ``ret=`` the finished episodes' mean, else ``ret so far=``
    the unfinished episodes' running return, else ``ret=nan`` (the empty string before the first chunk)."""
    if not row:
        return ""
    finished, running = row.get("episode_return", float("nan")), row.get("running_return", float("nan"))
    if np.isfinite(finished) or not np.isfinite(running):
        return f"ret={finished:.1f}"
    return f"ret so far={running:.1f}"


class _progress:
    """A tqdm bar over environment steps showing steps/s, the latest return and ETA (or nothing).

    The return shown is the mean over the episodes that ended in the latest chunk (``ret``); before any has
    ended (long episodes, few steps per arena), what the unfinished episodes have earned so far
    (``ret so far``), for agents whose metrics report ``running_return``."""

    def __init__(self, total: int, enabled: bool):
        self.bar = None
        if enabled:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=total, unit="step", unit_scale=True, dynamic_ncols=True, desc="training")

    def update(self, steps: int, row: dict) -> None:
        """Advances by ``steps`` environment steps; ``row``: the latest chunk's history row (may be empty)."""
        if self.bar is not None:
            self.bar.set_postfix_str(shown_return(row), refresh=False)
            self.bar.update(steps)

    def note(self, text: str) -> None:
        if self.bar is not None:
            self.bar.write(text)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def trained_arena(run_dir: Path, arena: Arena) -> Arena:
    """The arena a run trained on (its ``config.json``), whose batch state the checkpoint holds; ``arena``
    when it is the same or unknown. A policy trained on one arena may act in another with the same
    observation and action specs (e.g. trained with fast solver options, evaluated on the suite's)."""
    from jarena.building import build_arena

    saved = Path(run_dir) / "config.json"
    built_from = json.loads(saved.read_text()).get("arena") if saved.is_file() else None
    if not built_from or built_from in (arena.build_string, arena.name):
        return arena
    trained_on = build_arena(built_from)
    if trained_on.spec != arena.spec:
        raise ValueError(f"the run in {run_dir} trained on {built_from!r}, whose observation and action specs "
                         f"differ from {arena.build_string or arena.name!r}'s:\n  {trained_on.spec}\n  {arena.spec}")
    return trained_on


def seeds_run_of(path: str | os.PathLike) -> Path | None:
    """The :func:`train_seeds` run directory that ``path`` is a seed folder of (``RUN/seed_<s>``, whose run holds
    the config and the checkpoints), else ``None``."""
    path = Path(path)
    saved = path.parent / "config.json"
    if not path.name.startswith("seed_") or (path / "config.json").is_file() or not saved.is_file():
        return None
    return path.parent if "seeds" in json.loads(saved.read_text()) else None


def restore_policy(agent, arena: Arena, run_dir: str | os.PathLike, select: str = "best"):
    """The deterministic policy of a training run directory: the policy ``train_and_evaluate`` selected
    (``best``: the best validated one, kept in ``best_policy/``) or the latest checkpoint's (``last``, and
    for runs without a kept policy); a path to a checkpoints folder itself is taken as ``last``."""
    rule = selection(select)
    if getattr(agent, "init_training", None) is None:
        raise ValueError(f"agent {agent.name!r} is not trainable and has no checkpoints")
    path = Path(run_dir)
    if seeds_run_of(path) is not None:
        return _restore_seed_policy(agent, arena, path, rule)
    folder = path / "checkpoints" if (path / "checkpoints").is_dir() else path
    if rule.replaces is not None and (path / BEST_POLICY_DIR).is_dir():
        folder = path / BEST_POLICY_DIR
    checkpointer = Checkpointer(folder)
    if checkpointer.latest_step() is None:
        raise FileNotFoundError(f"no checkpoint found in {folder}")
    trained_on = trained_arena(path, arena)
    template = jax.jit(agent.init_training, static_argnums=1)(jax.random.key(0), trained_on)
    kept = folder.name == BEST_POLICY_DIR
    if kept:
        template = agent.policy(template, trained_on.spec, True)
    try:
        state, meta = checkpointer.restore(template)
    except Exception as e:  # orbax raises several types for a mismatched or damaged checkpoint
        raise ValueError(f"checkpoint in {folder} does not fit agent {agent.name!r} with config {agent.config} "
                         f"on {arena.name!r}: {e}") from e
    checkpointer.close()
    if kept:
        row = meta["validation"]
        print(f"restored the best validated policy (step {int(row['env_steps'])}, validation return "
              f"{row['return_mean']:.1f}) from {folder}")
        return state  # made for the trained-on arena's spec, which equals arena's (checked above)
    print(f"restored checkpoint {checkpointer.latest_step()} from {folder}")
    return agent.policy(state, arena.spec, True)


def _restore_seed_policy(agent, arena: Arena, seed_dir: Path, rule: Selection):
    """One seed's policy from the checkpoint of a :func:`train_seeds` run (``seed_dir``: its ``RUN/seed_<s>``):
    the one kept by the run's rule (``best``), or that seed's latest training state's (``last``, and when none
    was kept)."""
    run_dir = seed_dir.parent
    checkpointer = Checkpointer(run_dir / "checkpoints")
    try:
        if checkpointer.latest_step() is None:
            raise FileNotFoundError(f"no checkpoint found in {run_dir / 'checkpoints'}")
        seeds = checkpointer.metadata().get("seeds")
        seed = seed_dir.name.removeprefix("seed_")
        if seeds is None or not seed.isdigit() or int(seed) not in seeds:
            raise ValueError(f"{seed_dir}: the run in {run_dir} trained seeds {seeds}; give one of "
                             f"{[str(run_dir / f'seed_{s}') for s in seeds or []]}")
        index = seeds.index(int(seed))
        trained_on = trained_arena(run_dir, arena)
        train = _init_seeds(agent, trained_on, seeds)
        template = {"train": train, "kept": _stacked_policies(agent, trained_on.spec)(train)}
        try:
            state, meta = checkpointer.restore(template)
        except Exception as e:  # orbax raises several types for a mismatched or damaged checkpoint
            raise ValueError(f"checkpoint in {run_dir / 'checkpoints'} does not fit agent {agent.name!r} with config "
                             f"{agent.config} on {arena.name!r}: {e}") from e
        step = checkpointer.latest_step()
    finally:
        checkpointer.close()
    row = meta["kept_rows"][index]
    if rule.replaces is not None and row is not None:
        print(f"restored seed {seed}'s {rule.name} validated policy (step {int(row['env_steps'])}, validation return "
              f"{row['return_mean']:.1f}) from {run_dir / 'checkpoints' / str(step)}")
        return _seed_slice(state["kept"], index)
    print(f"restored seed {seed}'s training state of checkpoint {step} from {run_dir / 'checkpoints'}")
    return agent.policy(_seed_slice(state["train"], index), arena.spec, True)
