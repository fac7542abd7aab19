"""Evaluation results: per-episode values, aggregates with confidence intervals, and a text table."""

from __future__ import annotations

import dataclasses
import math

import numpy as np


def mean_interval(values: np.ndarray, confidence: float = 0.95) -> tuple[float, float, float, float]:
    """``(mean, std, low, high)``: sample std (ddof=1) and the Student-t interval of the mean."""
    values = np.asarray(values, np.float64)
    n = values.size
    if n == 0:
        return (math.nan,) * 4
    mean = float(values.mean())
    if n == 1:
        return mean, 0.0, mean, mean
    std = float(values.std(ddof=1))
    from scipy import stats  # a dependency of jax

    half = float(stats.t.ppf(0.5 + confidence / 2, n - 1)) * std / math.sqrt(n)
    return mean, std, mean - half, mean + half


@dataclasses.dataclass(frozen=True)
class EvalResult:
    """Results of evaluating an agent on a split's episodes (host numpy arrays, one entry per episode).

    Attributes:
      arena: the arena's name (its build string when it has one).
      agent: the agent's name.
      split: the split's name.
      episodes: int32 (N,) episode ids.
      returns: float (N,) undiscounted returns.
      lengths: int (N,) episode lengths in agent steps.
      successes: bool (N,) success at each episode's last step.
      metrics: name -> (N,) values at each episode's last step.
      has_success: whether the arena's task defines success; without one the success rate is "n/a"
        (left out of ``summary()``, ``None`` per episode), never 0%.
      faults: int32 (N,) fault bitmask of each episode (:mod:`jarena.core.faults`: an invalid action or
        non-finite state ended it, with reward 0 from that step), or ``None`` when not tracked.
      selected: which trained policy was evaluated, e.g. ``{"env_steps": ..., "validation_return": ...,
        "select": "best"}`` (set by :func:`jarena.train_and_evaluate`), or ``None``.
    """

    arena: str
    agent: str
    split: str
    episodes: np.ndarray
    returns: np.ndarray
    lengths: np.ndarray
    successes: np.ndarray
    metrics: dict[str, np.ndarray]
    has_success: bool = True
    faults: np.ndarray | None = None
    selected: dict | None = None

    @property
    def num_faulted(self) -> int:
        """Episodes that ended with a fault (0 when faults are not tracked)."""
        return 0 if self.faults is None else int(np.count_nonzero(self.faults))

    def summary(self) -> dict[str, float]:
        """Aggregates: return mean/std/95% interval, success rate (only when the task defines success), mean
        length, faulted episodes (when tracked), metric means."""
        mean, std, low, high = mean_interval(self.returns)
        out = {"episodes": float(self.returns.size), "return_mean": mean, "return_std": std,
               "return_ci95_low": low, "return_ci95_high": high}
        if self.has_success:
            out["success_rate"] = float(np.mean(self.successes)) if self.successes.size else math.nan
        out["length_mean"] = float(np.mean(self.lengths)) if self.lengths.size else math.nan
        if self.faults is not None:
            out["faulted_episodes"] = float(self.num_faulted)
        for name, values in sorted(self.metrics.items()):
            out[f"{name}_mean"] = float(np.mean(values))
        return out

    def per_episode(self) -> list[dict[str, float]]:
        """One row per episode: id, return, length, success and final metrics."""
        rows = []
        for i in range(self.episodes.size):
            row = {"episode": int(self.episodes[i]), "return": float(self.returns[i]),
                   "length": int(self.lengths[i]), "success": bool(self.successes[i]) if self.has_success else None}
            if self.faults is not None:
                row["fault"] = int(self.faults[i])
            row.update({k: float(v[i]) for k, v in sorted(self.metrics.items())})
            rows.append(row)
        return rows

    def table(self) -> str:
        """A results table as aligned text."""
        s = self.summary()
        rows = [("arena", self.arena), ("agent", self.agent), ("split", self.split),
                ("episodes", f"{int(s['episodes'])}"),
                ("return", f"{s['return_mean']:.2f} ± {s['return_std']:.2f}  "
                           f"(95% CI {s['return_ci95_low']:.2f} .. {s['return_ci95_high']:.2f})"),
                ("success rate",
                 f"{100 * s['success_rate']:.1f}%" if self.has_success else "n/a (the task defines none)"),
                ("mean length", f"{s['length_mean']:.1f}")]
        if self.faults is not None:
            rows.append(("faulted episodes", _faults_text(self.faults)))
        if self.selected is not None:
            rows.append(("policy", _selected_text(self.selected)))
        rows += [(name, f"{s[f'{name}_mean']:.4g}") for name in sorted(self.metrics)]
        width = max(len(k) for k, _ in rows)
        line = "+" + "-" * (width + 2) + "+" + "-" * (max(len(v) for _, v in rows) + 2) + "+"
        body = [f"| {k:<{width}} | {v:<{len(line) - width - 7}} |" for k, v in rows]
        return "\n".join([line, *body, line])

    def __str__(self):
        return self.table()


def _faults_text(faults: np.ndarray) -> str:
    """``0`` or ``3 (invalid action: 1, non-finite state: 2)``."""
    from jarena.core.faults import describe_counts

    count = int(np.count_nonzero(faults))
    if not count:
        return "0"
    return f"{count} (" + ", ".join(f"{name}: {n}" for name, n in describe_counts(faults).items()) + ")"


def _selected_text(selected: dict) -> str:
    """``best, step 430080 (validation return 500.0)`` or ``last, step 500736``."""
    text = f"{selected['select']}, step {int(selected['env_steps'])}"
    if selected.get("validation_return") is not None:
        text += f" (validation return {selected['validation_return']:.1f}"
        text += "".join(f", {k[len('validation_'):]} {v:.3g}" for k, v in selected.items()
                        if k.startswith("validation_") and k != "validation_return" and v is not None) + ")"
    return text
