"""Task transforms that compose with :func:`jarena.chain`."""

from jarena.tasks.goal_reaching import GoalReachingParams, goal_reaching
from jarena.tasks.reward_scale import reward_scale
from jarena.tasks.success_bonus import success_bonus
from jarena.tasks.time_limit import time_limit

__all__ = ["GoalReachingParams", "goal_reaching", "reward_scale", "success_bonus", "time_limit"]
