"""Difficulty tiers of crumpled cloth episodes: Agent-Arena's tier sizes, ranked by initial coverage."""

import jax
import numpy as np
import pytest

import jarena
from jarena.arenas.cloth.tiers import TIER_SIZES, difficulty_tiers, eval_tiers


def test_65_episodes_get_agent_arenas_tier_sizes_easiest_first():
    coverage = np.random.default_rng(0).uniform(0.2, 0.9, 65)
    tiers = difficulty_tiers(coverage)
    assert tuple(np.bincount(tiers)) == TIER_SIZES
    # every episode of a lower tier starts more covered than every episode of a higher one
    for t in range(len(TIER_SIZES) - 1):
        assert coverage[tiers == t].min() > coverage[tiers == t + 1].max()


def test_other_counts_keep_the_proportions():
    assert tuple(np.bincount(difficulty_tiers(np.linspace(1, 0, 130)))) == tuple(2 * s for s in TIER_SIZES)
    assert np.bincount(difficulty_tiers(np.linspace(1, 0, 64))).sum() == 64
    with pytest.raises(ValueError, match="positive"):
        difficulty_tiers(np.ones(4), (2, 0))


def test_eval_tiers_rank_an_arenas_eval_episodes():
    arena = jarena.build_arena("cloth|particles:8,resolution:16,initial:crumpled,eval_episodes:4")
    tiers = eval_tiers(arena, sizes=(1, 1, 2))
    assert sorted(e for ids in tiers.values() for e in ids) == sorted(int(e) for e in arena.episodes("eval"))
    assert [len(tiers[t]) for t in range(3)] == [1, 1, 2]
    # each episode reset alone (not batched as eval_tiers does), compiled once for all episodes
    reset_one = jax.jit(lambda e: arena.reset(episode=e)[1].metrics["normalised_coverage"])
    covered = {e: float(reset_one(e)) for e in arena.episodes("eval")}
    assert covered[tiers[0][0]] >= covered[tiers[1][0]] >= max(covered[e] for e in tiers[2])
    # (a flat start: the fold task's reset reports no coverage either way, and a flat reset compiles in a fraction
    # of a crumpled one's time)
    with pytest.raises(ValueError, match="normalised_coverage"):
        eval_tiers(jarena.build_arena("cloth|particles:8,resolution:16,task:side_fold,initial:flat,eval_episodes:2"))
