"""Difficulty tiers of crumpled cloth episodes, by initial coverage, as Agent-Arena's SoftGym tiers.

Agent-Arena evaluates flattening on SoftGym's ``mono-square-fabric`` in 5 tiers of its 65 crumpled eval
episodes, ranked by initial coverage: 3, 3, 10, 22 and 27 episodes from tier 0 (the most covered, easiest)
to tier 4 (the most crumpled). jarena's crumpled states are its own (generated on device from the episode
id, not SoftGym's cached ones), so the tiers keep Agent-Arena's proportions over whichever eval episodes an
arena has: the episodes ranked by initial normalised coverage, highest first, split in those proportions.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

TIER_SIZES = (3, 3, 10, 22, 27)
"""Agent-Arena's mono-square-fabric tiers: eval episodes per tier, tier 0 (easiest) first."""


def difficulty_tiers(initial_coverage, sizes: tuple[int, ...] = TIER_SIZES) -> np.ndarray:
    """int32 (E,): each episode's tier, from ``initial_coverage`` (E,) (normalised coverage at reset).

    Episodes ranked by coverage, highest first (ties in episode order), are cut in ``sizes``' proportions:
    with E = sum(sizes) the tiers have exactly those sizes; otherwise the cuts are rounded.
    """
    coverage = np.asarray(initial_coverage, np.float64).reshape(-1)
    if len(sizes) < 1 or any(int(s) < 1 for s in sizes):
        raise ValueError(f"tier sizes must be positive counts, got {sizes}")
    order = np.argsort(-coverage, kind="stable")
    cuts = np.round(np.cumsum(sizes) / np.sum(sizes) * coverage.size).astype(int)
    rank_tier = np.searchsorted(cuts, np.arange(coverage.size), side="right")
    tiers = np.empty(coverage.size, np.int32)
    tiers[order] = rank_tier
    return tiers


def eval_tiers(arena, sizes: tuple[int, ...] = TIER_SIZES, split: str = "eval") -> dict[int, list[int]]:
    """Tier -> episode ids of ``arena``'s ``split`` episodes (a cloth flattening arena: its reset reports
    ``normalised_coverage``); the resets run in one compiled batch."""
    episodes = [int(e) for e in arena.episodes(split)]
    reset = jax.jit(jax.vmap(lambda e: arena.reset(episode=e)[1].metrics))
    metrics = reset(jnp.asarray(episodes))
    if "normalised_coverage" not in metrics:
        raise ValueError(f"difficulty tiers rank episodes by normalised_coverage, which {arena.name} does not report "
                         "(build a cloth arena with task:flattening)")
    tiers = difficulty_tiers(metrics["normalised_coverage"], sizes)
    return {t: [e for e, k in zip(episodes, tiers, strict=True) if k == t] for t in range(len(sizes))}
