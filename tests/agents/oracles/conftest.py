import jax
import pytest

import jarena
import jarena_agents


@pytest.fixture(scope="session")
def evaluate_first_episodes():
    """``run(agent_name, arena_string, episodes=4)``: ``jarena.evaluate`` of the agent, built with its shipped
    config for the arena, on the arena's first eval episodes. Each call compiles one program (10-30 s for
    an MJX arena on a CPU), so tests share their results through module-scoped fixtures. The arena of each
    string is built once, so the agents evaluated on it share its traced reset shapes (its spec)."""
    arenas = {}

    def run(agent_name, spec, episodes=4):
        if spec not in arenas:
            arenas[spec] = jarena.build_arena(spec)
        arena = arenas[spec]
        agent = jarena_agents.build_agent(agent_name, jarena.retrieve_config(agent_name, arena))
        return jarena.evaluate(agent, arena, jax.random.key(0), episodes=list(arena.episodes("eval"))[:episodes])

    return run
