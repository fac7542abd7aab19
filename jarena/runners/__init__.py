"""Runners: one trial, evaluation over fixed splits, and batched device-parallel rollouts."""

from jarena.runners.evaluate import evaluate, evaluate_policies, validate
from jarena.runners.parallel import Rollout, perform_parallel
from jarena.runners.record import Recording, record_video
from jarena.runners.results import EvalResult, mean_interval
from jarena.runners.run import Trajectory, run

__all__ = ["EvalResult", "Recording", "Rollout", "Trajectory", "evaluate", "evaluate_policies", "mean_interval",
           "perform_parallel", "record_video", "run", "validate"]
