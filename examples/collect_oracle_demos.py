"""Collects a scripted oracle's demonstrations into a trajectory dataset (Agent-Arena's data collection).

    python examples/collect_oracle_demos.py --out demos/pendulum --trajectories 100
    python examples/collect_oracle_demos.py --agent oracle_cartpole --arena "classic|domain:cartpole,task:balance"

Run it again with the same ``--out`` to append more (it resumes; a killed run loses at most the
trajectories being written). ``--image H,W`` resizes image observations (arenas with a camera sensor).
"""

import argparse

import jax

import jarena
import jarena_agents


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agent", default="oracle_pendulum", help="a registered agent (default: %(default)s)")
    parser.add_argument("--arena", default="classic|domain:pendulum,task:swingup", help="an arena string")
    parser.add_argument("--out", default="demos/pendulum", help="dataset directory (appended to if it exists)")
    parser.add_argument("--trajectories", type=int, default=100, help="trajectories to add")
    parser.add_argument("--arenas", type=int, default=32, help="arenas run in parallel")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--image", default=None, help="resize image observations to H,W (e.g. 64,64)")
    args = parser.parse_args(argv)

    arena = jarena.build_arena(args.arena)
    agent = jarena_agents.build_agent(args.agent, jarena.retrieve_config(args.agent, arena))
    observe = jarena.data.resize_images(tuple(map(int, args.image.split(",")))) if args.image else None
    with jarena.TrajectoryDataset(args.out, "a", **jarena.data.configs_for(arena, observe)) as dataset:
        seed = args.seed + dataset.num_trajectories()  # resuming draws new episodes
        jarena.collect(agent, arena, dataset, args.trajectories, key=jax.random.key(seed), num_arenas=args.arenas,
                       observe=observe)
        returns = [float(t["reward"].sum()) for t in dataset]
        print(f"{dataset}: mean return {sum(returns) / len(returns):.1f}")


if __name__ == "__main__":
    main()
