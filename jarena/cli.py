"""The ``jarena`` command line: list arenas and agents, train and evaluate agents.

    jarena list
    jarena train ppo "classic|domain:cartpole" --run-dir runs/ppo-cartpole
    jarena evaluate oracle_cartpole "classic|domain:cartpole,task:balance"
    jarena evaluate random "classic|domain:pendulum" --split val --set key=value
    jarena collect oracle_pendulum "classic|domain:pendulum,task:swingup" --out demos/pendulum --trajectories 100
    jarena train bc "classic|domain:pendulum,task:swingup" --set dataset=demos/pendulum
    jarena render random "classic|domain:pendulum" --out pendulum.mp4 --episode 0 1 2 3
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import yaml


def select_arg(text: str) -> str:
    """``--select``: ``best``, ``last`` or ``best:<metric>``, checked as the argument is parsed."""
    from jarena.training import selection

    try:
        selection(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    return text


def parse_override(text: str) -> tuple[str, Any]:
    """``"key=value"`` -> ``(key, value)``, the value read as YAML (an argparse ``type`` for config overrides)."""
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"expected key=value, got {text!r}")
    key, value = text.split("=", 1)
    return key.strip(), yaml.safe_load(value)


def _cmd_list(args) -> int:
    import jarena
    import jarena_agents
    from jarena.building.builder import arena_tags

    print("Arenas (build with jarena.build_arena(string)):")
    strings = jarena.list_arenas(args.tag)
    width = max((len(s) for s in strings), default=0)
    for string in strings:
        print(f"  {string:<{width}}  [{', '.join(arena_tags(string))}]")
    print("\nAgents (build with jarena_agents.build_agent(name)):")
    width = max((len(entry.name) for entry in jarena_agents.AGENTS), default=0)
    for entry in jarena_agents.AGENTS:
        print(f"  {entry.name:<{width}}  [{', '.join(entry.tags)}]")
    return 0


def _agent_config(args, arena) -> dict:
    """The agent's config for ``arena``: the tuned one (``--config``), or with ``--checkpoint`` the one the
    run trained with, then the ``--set`` overrides.

    On arenas without a tuned ``default`` config the agent runs on its built-in defaults (with a note on
    stderr, except for agents tagged ``arena_model``). Those (the planners, the cloth oracles'
    lookahead) simulate the arena they act in: their config's ``arena`` is the evaluated arena's string.
    """
    import jarena
    import jarena_agents
    from jarena.training import seeds_run_of

    models_arena = args.agent in jarena_agents.list_agents("arena_model")  # it simulates the arena it acts in
    try:
        config = jarena.retrieve_config(args.agent, arena, args.config)
    except FileNotFoundError as e:
        if args.config != "default":  # a named config that is missing is an error
            raise
        if not models_arena:
            print(f"note: {e}; using {args.agent}'s built-in defaults (and any --set)", file=sys.stderr)
        config = {}
    if models_arena:
        config["arena"] = args.arena
    checkpoint = getattr(args, "checkpoint", None)
    run = checkpoint and (seeds_run_of(checkpoint) or checkpoint)  # a seed of a --seeds run: the run's config
    saved = Path(run or "", "config.json")
    if checkpoint and saved.is_file():
        config = json.loads(saved.read_text()).get("config") or config  # the config the run trained with
    config.update(dict(args.set or []))
    return config


def _cmd_evaluate(args) -> int:
    from jarena import distributed

    distributed.initialize(_launch(args))  # before any computation: every process joins the run
    import jax

    import jarena
    import jarena_agents
    from jarena.runners.evaluate import run_episodes
    from jarena.training import restore_policy

    main = distributed.is_main_process()
    say = print if main else (lambda *a, **k: None)
    arena = jarena.build_arena(args.arena)
    config = _agent_config(args, arena)
    agent = jarena_agents.build_agent(args.agent, config)
    agent_state = None
    if args.checkpoint:
        agent_state = restore_policy(agent, arena, args.checkpoint, args.select)
    episodes = list(arena.episodes(args.split))[: args.episodes] if args.episodes else None
    n = len(episodes) if episodes is not None else len(arena.episodes(args.split))
    filmed, write = _filming(arena, min(_count(args.videos, "--videos"), n), main, args.arena)
    devices = distributed.mesh(args.devices).devices.size
    say(f"evaluating {agent.name!r} on {args.arena!r}: {n} {args.split} episodes in parallel "
        f"on {devices} {jax.default_backend()} device(s) ...", flush=True)
    start = time.perf_counter()
    result, physics = run_episodes(agent, arena, jax.random.key(args.seed), split=args.split, episodes=episodes,
                                   agent_state=agent_state, filmed=filmed, devices=args.devices)
    # the collective part ends here: what follows works on host copies, and only process 0 writes
    if not main:
        return 0
    seconds = time.perf_counter() - start
    steps = int(result.lengths.sum())
    print(f"done in {seconds:.1f} s (compile included), {steps} agent steps")
    print(result.table())
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"summary": result.summary(), "episodes": result.per_episode()}, f, indent=2)
        print(f"wrote {args.json}")
    if write:  # after the results: a failing encoder or renderer costs the videos only
        _write_videos(arena, physics, result, Path(args.video_dir), filmed)
    return 0


def _filming(arena, videos: int, main: bool, name: str) -> tuple[int, bool]:
    """``(filmed, write)``: how many episodes the evaluation films (the same in every process: it shapes the
    compiled program, which all processes must share) and whether this process writes them (process 0, where it
    can render; a renderer that fails here is a warning, not a lost evaluation)."""
    from jarena.render.frames import RenderError, can_render
    from jarena.render.record import check_video

    if not videos:
        return 0, False
    if not can_render(arena):
        if main:
            print(f"warning: no videos: arena {name!r} has no renderer", file=sys.stderr)
        return 0, False
    if not main:
        return videos, False
    try:
        check_video(arena)
    except RenderError as e:
        print(f"warning: no videos: {e}", file=sys.stderr)
        return videos, False
    return videos, True


def _count(value: int, flag: str) -> int:
    if value < 0:
        raise ValueError(f"{flag} must be 0 (none) or more, got {value}")
    return value


def _write_videos(arena, physics, result, folder: Path, videos: int) -> None:
    """Writes the filmed episodes' videos; a failure is a warning on stderr that names the fix."""
    from jarena.render.record import write_episodes
    from jarena.training import VIDEO_FIXES

    paths = [folder / f"{result.split}_episode_{int(i)}" for i in result.episodes[:videos]]
    try:
        written = write_episodes(arena, physics, result.lengths[:videos], paths)
    except Exception as e:  # the results are printed and written already
        print(f"warning: videos not written ({type(e).__name__}: {e}). To get videos: {VIDEO_FIXES}",
              file=sys.stderr)
        return
    print(f"wrote {len(written)} video(s) to {folder}")


def _launch(args):
    """The multi-process launch the flags (or the JARENA_* variables) describe, or None for one process."""
    from jarena import distributed

    given = {"--coordinator": args.coordinator, "--num-processes": args.num_processes,
             "--process-id": args.process_id}
    if all(v is None for v in given.values()):
        return distributed.launch_from_environment()
    missing = [flag for flag, v in given.items() if v is None]
    if missing:
        raise ValueError(f"a multi-process launch needs --coordinator, --num-processes and --process-id; missing "
                         f"{', '.join(missing)}")
    return distributed.Launch(args.coordinator, args.num_processes, args.process_id)


def _add_launch_flags(parser: argparse.ArgumentParser, devices_help: str) -> None:
    """``--devices`` and the multi-process launch flags, shared by the commands that run on a device mesh."""
    group = parser.add_argument_group(
        "devices and processes",
        "The arenas are split over the devices, the networks replicated, and the results are what one device "
        "computes. For several processes (hosts), start the same command in each with its --process-id (or "
        "set JARENA_COORDINATOR, JARENA_NUM_PROCESSES, JARENA_PROCESS_ID, e.g. from SLURM's $SLURM_NTASKS and "
        "$SLURM_PROCID); process 0 prints and writes the outputs, so paths must be on a filesystem all "
        "processes share. A process that dies or hangs makes the others stop within JARENA_HEARTBEAT_TIMEOUT "
        "(default 60) or JARENA_WAIT_TIMEOUT (default 900) seconds, naming it; SIGTERM ends every command "
        "promptly, keeping what it saved.")
    group.add_argument("--devices", default=None, metavar="N|all", help=devices_help)
    group.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                       help="address of process 0's coordination service")
    group.add_argument("--num-processes", type=int, default=None, metavar="N", help="processes in the run")
    group.add_argument("--process-id", type=int, default=None, metavar="I", help="this process, 0 .. N-1")


def _cmd_train(args) -> int:
    from jarena import distributed

    distributed.initialize(_launch(args))  # before any computation: every process joins the run
    import jax

    import jarena
    import jarena_agents
    from jarena.training import train_and_evaluate

    say = print if distributed.is_main_process() else (lambda *a, **k: None)
    if args.seeds < 1:
        raise ValueError(f"--seeds must be 1 or more, got {args.seeds}")
    if args.seeds > 1 and (jax.process_count() > 1 or args.devices not in (None, 1, "1")):
        raise ValueError("--seeds trains its seeds in one program on one device; leave out --devices and the launch "
                         "flags (or train each seed as its own run)")
    arena = jarena.build_arena(args.arena)
    eval_arena = jarena.build_arena(args.eval_arena) if args.eval_arena else None
    config = _agent_config(args, arena)
    if args.steps is not None:
        config["total_steps"] = args.steps
    agent = jarena_agents.build_agent(args.agent, config)
    settings = getattr(agent, "settings", None)
    steps = settings.total_steps if settings is not None else args.steps
    unit = getattr(settings, "step_unit", "environment steps")  # bc: gradient updates
    mesh = distributed.mesh(args.devices)
    where = (f"{mesh.devices.size} {jax.default_backend()} device(s)" if jax.process_count() == 1 else
             f"{mesh.devices.size} {jax.default_backend()} devices of {jax.process_count()} processes")
    seeds = f"seed {args.seed}" if args.seeds == 1 else f"seeds {args.seed} to {args.seed + args.seeds - 1}, at once"
    say(f"training {agent.name!r} on {args.arena!r} for {steps} {unit} on {where} ({seeds})"
        + (f"; validating and evaluating on {args.eval_arena!r}" if eval_arena is not None else ""), flush=True)
    if args.seeds > 1:
        return _train_seeds(args, agent, arena, eval_arena, say)
    result = train_and_evaluate(agent, arena, jax.random.key(args.seed), run_dir=args.run_dir,
                                progress=not args.no_progress, select=args.select,
                                eval_videos=_count(args.videos, "--videos"), devices=args.devices,
                                eval_arena=eval_arena, **_validation_schedule(args.validations))
    last = result.history[-1]
    say(f"trained {last['env_steps']} steps in {last['seconds']:.1f} s "
          f"({last['env_steps'] / max(last['seconds'], 1e-9):.3g} steps/s, compile included)")
    say(result.evaluation.table())
    if args.run_dir:
        say(f"run directory: {args.run_dir} (config, train.csv, validation.csv, evaluation.json, "
              "learning_curve.png" + (", videos/" if Path(args.run_dir, "videos").is_dir() else "") + ")")
    return 0


def _train_seeds(args, agent, arena, eval_arena, say) -> int:
    """``jarena train --seeds N``: seeds ``--seed`` .. ``--seed + N - 1`` in one compiled program."""
    from jarena.training import train_seeds

    seeds = range(args.seed, args.seed + args.seeds)
    result = train_seeds(agent, arena, seeds, run_dir=args.run_dir, progress=not args.no_progress,
                         eval_arena=eval_arena, select=args.select, **_validation_schedule(args.validations))
    last = result.histories[0][-1]
    say(f"trained {len(seeds)} seeds x {last['env_steps']} steps in {last['seconds']:.1f} s, compile included; "
        f"each seed's {args.select} policy on the eval episodes:")
    say(result.table())
    if args.run_dir:
        say(f"run directory: {args.run_dir} (config.json, seeds.csv, checkpoints/, seed_<s>/ with train.csv, "
            f"validation.csv, evaluation.json and learning_curve.png)")
    return 0


def _validation_schedule(validations: int) -> dict:
    """``train_and_evaluate``'s validation arguments for ``--validations N`` (0: never validate)."""
    count = _count(validations, "--validations")
    return {"validate_every": 0} if count == 0 else {"validations": count}


def _cmd_collect(args) -> int:
    from jarena import distributed

    distributed.initialize(_launch(args))  # before any computation: every process joins the run
    import jax
    import numpy as np

    import jarena
    import jarena_agents
    from jarena.data.dataset import TrajectoryDataset

    if args.trajectories < 1:
        raise ValueError(f"--trajectories must be at least 1, got {args.trajectories}")
    if args.batch is not None and args.batch < 1:
        raise ValueError(f"--batch must be at least 1, got {args.batch}")
    if args.append and args.overwrite:
        raise ValueError("--append and --overwrite exclude each other: add to the dataset, or replace it")
    main = distributed.is_main_process()
    arena = jarena.build_arena(args.arena)
    config = _agent_config(args, arena)
    agent = jarena_agents.build_agent(args.agent, config)
    if not (math.isfinite(args.action_noise) and args.action_noise >= 0):
        raise ValueError(f"--action-noise must be a finite number >= 0, got {args.action_noise}")
    if not 0 <= args.random_actions <= 1:
        raise ValueError(f"--random-actions must be a probability in [0, 1], got {args.random_actions}")
    if args.action_noise or args.random_actions:  # demonstrations mixed with noisier ones
        agent = jarena_agents.noisy(agent, action_noise=args.action_noise, random_fraction=args.random_actions)
    exists = Path(args.out, "zarr.json").is_file()
    if exists and not (args.append or args.overwrite):
        held = TrajectoryDataset(args.out).num_trajectories()
        raise ValueError(f"{args.out} already holds a dataset ({held} trajectories); pass --append to add to it "
                         "or --overwrite to replace it")
    # every process reads how many trajectories are stored (the key depends on it); only process 0 writes
    before = TrajectoryDataset(args.out).num_trajectories() if exists and args.append else 0
    dataset = (TrajectoryDataset(args.out, "a" if args.append else "w", **jarena.data.configs_for(arena))
               if main else None)
    try:
        devices = distributed.mesh(args.devices).devices.size
        num_arenas = args.batch or -(-min(args.trajectories, 64) // devices) * devices  # splits over the devices
        if main:
            print(f"collecting {args.trajectories} trajectories of {agent.name!r} on {args.arena!r} into {args.out} "
                  f"({num_arenas} arenas in parallel on {devices} {jax.devices()[0].platform} device(s), seed "
                  f"{args.seed})", flush=True)
        start = time.perf_counter()
        # Appending folds the trajectories already there into the key, so each run adds new episodes.
        stored = jarena.collect(agent, arena, dataset, args.trajectories, key=jax.random.fold_in(
            jax.random.key(args.seed), before), num_arenas=num_arenas, progress=not args.no_progress,
            devices=args.devices)
        # the collective part ends here: process 0 alone reads its dataset back and prints
        if not main:
            return 0
        seconds = time.perf_counter() - start
        lengths = dataset.lengths()
        first_step = int(lengths[:stored[0]].sum())
        new = lengths[stored[0]:]
        rewards = dataset.rows("step/reward", first_step, first_step + int(new.sum())).astype(np.float64)
        returns = np.add.reduceat(rewards, np.concatenate([[0], np.cumsum(new)[:-1]]))
        print(f"stored {len(stored)} trajectories ({int(new.sum())} transitions) in {seconds:.1f} s: return "
              f"{returns.mean():.2f} +- {returns.std():.2f} (mean +- std), length {new.mean():.1f}")
        print(f"dataset {args.out}: {dataset.num_trajectories()} trajectories, {dataset.num_steps()} transitions")
    finally:
        if dataset is not None:
            dataset.close()
    print(f'clone it with: jarena train bc "{args.arena}" --set dataset={args.out}')
    return 0


def _cmd_render(args) -> int:
    import jax

    import jarena
    import jarena_agents
    from jarena.render import renderer
    from jarena.runners import record_video
    from jarena.training import restore_policy

    arena = jarena.build_arena(args.arena)
    renderer(arena)  # a clear error before the agent is built
    config = _agent_config(args, arena)
    agent = jarena_agents.build_agent(args.agent, config)
    agent_state = restore_policy(agent, arena, args.checkpoint, args.select) if args.checkpoint else None
    camera = int(args.camera) if args.camera.lstrip("-").isdigit() else args.camera
    print(f"filming {agent.name!r} on {args.arena!r}, episode(s) {args.episode} ...", flush=True)
    start = time.perf_counter()
    rec = record_video(agent, arena, args.out, args.episode, key=jax.random.key(args.seed), agent_state=agent_state,
                       width=args.width, height=args.height, camera=camera, max_steps=args.max_steps, fps=args.fps,
                       format=args.format)
    returns = ", ".join(f"{r:.2f}" for r in rec.result.returns)
    print(f"wrote {rec.path}: {rec.frames} frames at {rec.fps:g} fps, {rec.path.stat().st_size / 1024:.0f} KiB "
          f"in {time.perf_counter() - start:.1f} s (compile included); episode return(s) {returns}")
    return 0


class _DefaultsHelp(argparse.ArgumentDefaultsHelpFormatter):
    """Adds ``(default: X)`` to an option's help unless X is None or False (an unset option, an off switch) or the
    help already says its default."""

    def _get_help_string(self, action):
        text = action.help or ""
        unset = action.default is None or action.default is False or action.default == argparse.SUPPRESS
        if unset or "default:" in text or "%(default)" in text:
            return text
        return super()._get_help_string(action)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="jarena", description="JAX-native arenas and agents.",
        epilog="Compiled programs are kept in JAX's persistent compilation cache, so a second run of the same agent "
               "and arena starts at once: in ~/.cache/jarena/xla ($XDG_CACHE_HOME/jarena/xla), or the directory "
               "in JARENA_COMPILATION_CACHE (off: JARENA_COMPILATION_CACHE=off; a JAX_COMPILATION_CACHE_DIR of "
               "your own is used as it is).")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("list", help="list buildable arenas and registered agents")
    p.add_argument("--tag", default=None, help="only arenas with this tag (e.g. benchmark)")
    p.set_defaults(fn=_cmd_list)

    p = sub.add_parser("train", help="train an agent, validating periodically, then evaluate it and print a table",
                       formatter_class=_DefaultsHelp)
    p.add_argument("agent", help="trainable agent name (e.g. ppo)")
    p.add_argument("arena", help='arena string, e.g. "classic|domain:cartpole"')
    p.add_argument("--steps", type=int, default=None,
                   help="environment steps, or gradient updates for agents that learn from a dataset such as bc "
                        "(default: the config's total_steps)")
    p.add_argument("--seed", type=int, default=0, help="seed of the whole run")
    p.add_argument("--run-dir", default=None, help="write logs, results and a learning-curve plot here")
    p.add_argument("--config", default="default", help="config name under configs/<agent>/<arena>/")
    p.add_argument("--set", action="append", type=parse_override, metavar="KEY=VALUE",
                   help="override a config key (repeatable)")
    p.add_argument("--select", default="best", type=select_arg, metavar="best|last|best:METRIC",
                   help="which policy the final evaluation runs: the one with the best validation return (ties: "
                        "the latest), the last one, or the best by a validation.csv column (e.g. "
                        "best:success_rate, best:max_coverage_mean)")
    p.add_argument("--videos", type=int, default=2, metavar="N",
                   help="film the first N eval episodes into RUN_DIR/videos (0: none); written after the results, "
                        "so a missing encoder or renderer costs only the videos")
    p.add_argument("--validations", type=int, default=10, metavar="N",
                   help="validate at most N times in the run, evenly spaced, the last after the final update "
                        "(0: never; each validation runs the arena's validation episodes to their end)")
    p.add_argument("--seeds", type=int, default=1, metavar="N",
                   help="train N seeds (--seed .. --seed + N - 1) at once in one compiled program (for runs that leave "
                        "the device idle), validating them together, and evaluate each seed's policy chosen by "
                        "--select (with --run-dir it checkpoints, and the same command resumes it)")
    p.add_argument("--eval-arena", default=None, metavar="ARENA",
                   help="validate and evaluate on this arena's episodes instead (the same observation and action "
                        "specs): train on cheaper physics, e.g. \"dmc|domain:walker,task:walk,iterations:2\", and "
                        "report the return on the reference, \"dmc|domain:walker,task:walk\"")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    _add_launch_flags(p, "devices to train on: 'all', or a count (default: all in a multi-process run, else 1)")
    p.set_defaults(fn=_cmd_train)

    p = sub.add_parser("evaluate", help="evaluate an agent on an arena's fixed episodes and print a results table",
                       formatter_class=_DefaultsHelp)
    p.add_argument("agent", help="agent name, see `jarena list`")
    p.add_argument("arena", help='arena string, e.g. "classic|domain:cartpole,task:balance"')
    p.add_argument("--split", default="eval", choices=["eval", "val"], help="which fixed episodes")
    p.add_argument("--episodes", type=int, default=None, help="only the first N episodes of the split")
    p.add_argument("--seed", type=int, default=0, help="seed of the agent's randomness")
    p.add_argument("--config", default="default", help="config name under configs/<agent>/<arena>/")
    p.add_argument("--set", action="append", type=parse_override, metavar="KEY=VALUE",
                   help="override a config key (repeatable)")
    p.add_argument("--checkpoint", default=None, metavar="RUN_DIR",
                   help="evaluate a training run's policy (see --select); RUN_DIR/seed_<s> for one seed of a "
                        "--seeds run")
    p.add_argument("--select", default="best", type=select_arg, metavar="best|last|best:METRIC",
                   help="with --checkpoint: the run's best validated policy (what `jarena train` evaluated, "
                        "whichever rule kept it) or its latest checkpoint")
    p.add_argument("--json", default=None, help="also write the summary and per-episode results to this file")
    p.add_argument("--videos", type=int, default=0, metavar="N", help="film the first N episodes (0: none)")
    p.add_argument("--video-dir", default="videos", help="folder for --videos")
    _add_launch_flags(p, "split the episodes over this many devices, or 'all' (default: all in a multi-process "
                         "run, else 1); the results are the same")
    p.set_defaults(fn=_cmd_evaluate)

    p = sub.add_parser(
        "collect", help="run an agent on an arena and store its finished episodes in a trajectory dataset",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Runs AGENT (e.g. a scripted oracle) on a batch of ARENA's training episodes, stores the first\n"
                    "N to finish (observations, actions, rewards) in a zarr TrajectoryDataset at PATH and prints\n"
                    "their mean return. Read it with jarena.TrajectoryDataset(PATH).",
        epilog="example (oracle demonstrations, then behaviour cloning on them):\n"
               '  jarena collect oracle_pendulum "classic|domain:pendulum,task:swingup" --out demos/pendulum '
               "--trajectories 100\n"
               '  jarena train bc "classic|domain:pendulum,task:swingup" --set dataset=demos/pendulum')
    p.add_argument("agent", help="agent name, see `jarena list` (e.g. oracle_pendulum, oracle_cartpole)")
    p.add_argument("arena", help='arena string, e.g. "classic|domain:pendulum,task:swingup"')
    p.add_argument("--out", required=True, metavar="PATH", help="dataset directory")
    p.add_argument("--trajectories", type=int, required=True, metavar="N", help="finished episodes to store")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the episodes and the agent (default: 0; with --append it is combined with the "
                        "number of trajectories already stored, so each run adds new episodes)")
    p.add_argument("--config", default="default",
                   help="agent config name under configs/<agent>/<arena>/ (default: default)")
    p.add_argument("--set", action="append", type=parse_override, metavar="KEY=VALUE",
                   help="override a config key of the agent (repeatable)")
    p.add_argument("--batch", type=int, default=None, metavar="B",
                   help="arenas run in parallel (default: min(N, 64), rounded up to split evenly over the devices)")
    p.add_argument("--action-noise", type=float, default=0.0, metavar="STD",
                   help="add Gaussian noise to the agent's float actions, STD half ranges of each element, clipped "
                        "to the action spec (jarena_agents.noisy; default: 0)")
    p.add_argument("--random-actions", type=float, default=0.0, metavar="P",
                   help="in each arena and step, with probability P act uniformly at random instead (default: 0)")
    p.add_argument("--append", action="store_true",
                   help="add to the dataset at PATH (its configs must match the arena's) instead of creating one")
    p.add_argument("--overwrite", action="store_true", help="replace a dataset already at PATH")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    _add_launch_flags(p, "split the arenas over this many devices, or 'all' (default: all in a multi-process run, "
                         "else 1); the trajectories are the same")
    p.set_defaults(fn=_cmd_collect)
    p = sub.add_parser("render", help="film an agent's episodes in an arena and write an MP4 or GIF video",
                       formatter_class=_DefaultsHelp)
    p.add_argument("agent", help="agent name, see `jarena list`")
    p.add_argument("arena", help='arena string, e.g. "classic|domain:pendulum" (its dynamics must render)')
    p.add_argument("--out", required=True, help="video file, .mp4 or .gif (no suffix: --format's)")
    p.add_argument("--episode", type=int, nargs="+", default=[0],
                   help="episode id(s), 0.. are the eval split's; several are tiled into a grid")
    p.add_argument("--seed", type=int, default=0, help="seed of the agent's randomness")
    p.add_argument("--config", default="default", help="config name under configs/<agent>/<arena>/")
    p.add_argument("--set", action="append", type=parse_override, metavar="KEY=VALUE",
                   help="override a config key (repeatable)")
    p.add_argument("--checkpoint", default=None, metavar="RUN_DIR",
                   help="film a training run's policy (see --select)")
    p.add_argument("--select", default="best", type=select_arg, metavar="best|last|best:METRIC",
                   help="with --checkpoint: the run's best validated policy or its latest checkpoint")
    p.add_argument("--width", type=int, default=320, help="frame width in pixels (per episode)")
    p.add_argument("--height", type=int, default=240, help="frame height in pixels (per episode)")
    p.add_argument("--camera", default="-1", help="MuJoCo camera name or id (-1: free camera)")
    p.add_argument("--format", default=None, choices=["mp4", "gif"], help="video format (default: --out's suffix)")
    p.add_argument("--max-steps", type=int, default=None, help="step cap (default: the arena's episode length)")
    p.add_argument("--fps", type=float, default=None, help="playback rate (default: real time)")
    p.set_defaults(fn=_cmd_render)
    return parser


def main(argv: list[str] | None = None) -> int:
    from jarena import termination, watchdog
    from jarena.platform import avoid_cpu_eigen_deadlock, enable_compilation_cache

    avoid_cpu_eigen_deadlock()
    args = build_parser().parse_args(argv)
    enable_compilation_cache()
    termination.on_signal(watchdog.terminated)  # the other processes of a run learn of it at once
    with termination.handling():  # SIGTERM: every command ends promptly, keeping what it saved
        return _run(args)


def _run(args) -> int:
    """Runs the command; errors become messages (and in a multi-process run, stop the other processes too)."""
    from jarena import termination, watchdog

    try:
        return args.fn(args)
    except (termination.Terminated, KeyboardInterrupt) as e:
        why, status = (("received SIGTERM", termination.EXIT_STATUS) if isinstance(e, termination.Terminated)
                       else ("interrupted", 130))
        # a multi-process run: tell the others and leave without JAX's shutdown barrier (they may be gone)
        watchdog.fail(f"it {why}" if why.startswith("received") else f"it was {why}", status)
        print(f"jarena: stopped: {why}; what was saved is kept (a training run with a run directory resumes from "
              "its last checkpoint when started again with the same command)", file=sys.stderr, flush=True)
        return status
    except (ValueError, KeyError, FileNotFoundError) as e:
        print(f"jarena: error: {e}", file=sys.stderr, flush=True)
        watchdog.crashed(e, 2)  # a multi-process run: the others stop at once
        return 2
    except Exception as e:
        if watchdog.current() is None:
            raise
        import traceback

        traceback.print_exc()
        watchdog.crashed(e, 1)
        raise


if __name__ == "__main__":
    sys.exit(main())
