"""Arena steps simulated per second inside the sampling planners (``mppi``, ``cem``, ``predictive_sampling``).

One measurement is one jitted ``agent.act`` of a planner for B arenas at once: each arena plans from its
own privileged state with N sampled plans of horizon H, for the planner's iterations, so one act
simulates ``B x N x H x iterations`` arena steps (``arena.step`` of the real arena, ``lax.scan`` over the
horizon, ``vmap`` over samples and arenas). Compilation (``jit(...).lower(...).compile()``) is timed apart;
then one warm-up call and ``--repeats`` timed calls (``time.perf_counter`` around the call and
``jax.block_until_ready``), interleaved across the planners so that a change in the machine's load weighs
on all of them alike. The table shows the best call; the JSON beside ``--out`` also the median.

- plans/s: arena-plans per second, ``B / seconds`` (one plan = one act for one arena: a control rate).
- steps/s: arena steps simulated per second, ``B x N x H x iterations / seconds``.

Usage::

    python benchmarks/planning_throughput.py --help
    # CPU, small settings (a minute or so on 2 cores):
    python benchmarks/planning_throughput.py --samples 64,256 --arenas 4 --horizon 10 --repeats 3
    # GPU defaults: N = 256, 1024, 4096, B = 16 arenas, H = 30:
    python benchmarks/planning_throughput.py --out results/planning_gpu.md
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import sys
import time

import jax

try:
    import jarena
except ImportError:  # run from a checkout without installing: put the repository root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import jarena
import jarena_agents  # noqa: E402

PLANNERS = ("mppi", "cem", "predictive_sampling")


def _ints(text: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None
    if not values or min(values) < 1:
        raise argparse.ArgumentTypeError(f"expected positive integers, got {text!r}")
    return values


def _planners(text: str) -> list[str]:
    names = [v.strip() for v in text.split(",") if v.strip()]
    unknown = sorted(set(names) - set(PLANNERS))
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"unknown planner(s) {unknown}; choose from {list(PLANNERS)}")
    return names


def compile_act(name: str, arena, samples: int, horizon: int, iterations: int | None, arenas: int) -> dict:
    """Builds planner ``name`` for ``arena`` and compiles its act for ``arenas`` arenas."""
    config = {"samples": samples, "horizon": horizon}
    if iterations is not None:
        config["iterations"] = iterations
    agent = jarena_agents.build_agent(name, dict(config, arena=arena.build_string))
    key = jax.random.key(0)
    agent_state = agent.init(key, arena.spec, arenas)
    state, info = jax.jit(lambda k: jarena.batch_reset(arena, k, arenas))(key)
    args = (agent_state, info, jax.random.key(1), arena.privileged(state))
    t0 = time.perf_counter()
    compiled = jax.jit(agent.act).lower(*args).compile()
    compile_s = time.perf_counter() - t0
    jax.block_until_ready(compiled(*args))  # warm-up
    steps = arenas * samples * horizon * agent.config["iterations"]
    return {"compiled": compiled, "args": args, "compile_s": compile_s, "steps": steps,
            "iterations": agent.config["iterations"]}


def time_samples(names: list[str], arena, samples: int, horizon: int, iterations: int | None, arenas: int,
                 repeats: int) -> list[dict]:
    """Times every planner at one sample count; one row per planner."""
    progs = {n: compile_act(n, arena, samples, horizon, iterations, arenas) for n in names}
    times = {n: [] for n in names}
    for _ in range(repeats):
        for n, p in progs.items():
            t0 = time.perf_counter()
            jax.block_until_ready(p["compiled"](*p["args"]))
            times[n].append(time.perf_counter() - t0)
    rows = []
    for n in names:
        best, median = min(times[n]), statistics.median(times[n])
        p = progs[n]
        rows.append({"planner": n, "samples": samples, "horizon": horizon, "iterations": p["iterations"],
                     "arenas": arenas, "compile_s": p["compile_s"], "best_s": best, "median_s": median,
                     "plans_per_s": arenas / best, "steps_per_s": p["steps"] / best,
                     "steps_per_s_median": p["steps"] / median})
    return rows


def table(rows: list[dict]) -> str:
    head = "| planner | N | H | iters | B | compile s | act ms | plans/s | arena steps/s |"
    lines = [head, "|" + " --- |" * 9]
    for r in rows:
        lines.append(f"| {r['planner']} | {r['samples']} | {r['horizon']} | {r['iterations']} | {r['arenas']} | "
                     f"{r['compile_s']:.1f} | {1000 * r['best_s']:.2f} | {r['plans_per_s']:.3g} | "
                     f"{r['steps_per_s']:.3g} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    jax.config.update("jax_enable_compilation_cache", False)  # compile times are measured: never load them
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--arena", default="classic|domain:pendulum", help="arena string (continuous actions)")
    parser.add_argument("--planners", type=_planners, default=list(PLANNERS), help="comma-separated planners")
    parser.add_argument("--samples", type=_ints, default=[256, 1024, 4096], help="N values, comma-separated")
    parser.add_argument("--horizon", type=int, default=30, help="H, plan length in agent steps")
    parser.add_argument("--iterations", type=int, default=None,
                        help="sampling rounds per act (default: each planner's own, cem 4, others 1)")
    parser.add_argument("--arenas", type=int, default=16, help="B, arenas planned for in one act")
    parser.add_argument("--repeats", type=int, default=10, help="timed calls per planner and N")
    parser.add_argument("--out", default=None, help="write the table to FILE.md and the rows to FILE.json")
    args = parser.parse_args(argv)

    from jarena.platform import avoid_cpu_eigen_deadlock

    avoid_cpu_eigen_deadlock()
    arena = jarena.build_arena(args.arena)
    device = jax.devices()[0]
    print(f"planning throughput on {device.platform} ({device.device_kind}), arena {args.arena!r}", flush=True)
    rows = []
    for samples in args.samples:
        new = time_samples(args.planners, arena, samples, args.horizon, args.iterations, args.arenas, args.repeats)
        for r in new:
            print(f"  {r['planner']:20s} N={samples:<6d} {1000 * r['best_s']:9.2f} ms/act  "
                  f"{r['steps_per_s']:.3g} arena steps/s", flush=True)
        rows += new
    text = table(rows)
    print(text)
    if args.out:
        base = args.out[:-3] if args.out.endswith(".md") else args.out
        os.makedirs(os.path.dirname(base) or ".", exist_ok=True)
        with open(base + ".md", "w") as f:
            f.write(text + "\n")
        env = {"date": datetime.datetime.now().isoformat(timespec="seconds"), "jax": jax.__version__,
               "device": f"{device.platform} ({device.device_kind})", "python": platform.python_version(),
               "machine": platform.machine(), "cpus": os.cpu_count()}
        with open(base + ".json", "w") as f:
            json.dump({"environment": env, "arguments": vars(args), "rows": rows}, f, indent=2)
        print(f"wrote {base}.md and {base}.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
