"""Discrete-time LQR gains of a MuJoCo model, linearised on the host (numpy/scipy) at build time.

``linearise`` differentiates one ``mj_step`` (whatever the model's integrator, RK4 included, which
``mujoco.mjd_transitionFD`` does not support) by central finite differences about a state and control:
``s' ~ s0' + A (s - s0) + B (u - u0)`` with ``s = (qpos, qvel)``. ``lqr_gain`` solves the discrete
algebraic Riccati equation for the feedback ``u = u0 - K (s - s0)`` minimising
``sum s^T Q s + u^T R u`` over control steps.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import mujoco


def _step(model: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray, ctrl: np.ndarray, n_sub_steps: int
          ) -> np.ndarray:
    import mujoco

    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:], data.ctrl[:] = qpos, qvel, ctrl
    mujoco.mj_step(model, data, nstep=n_sub_steps)
    return np.concatenate([data.qpos, data.qvel])


def linearise(model: mujoco.MjModel, qpos, qvel=None, ctrl=None, *, n_sub_steps: int = 1, eps: float = 1e-6
              ) -> tuple[np.ndarray, np.ndarray]:
    """``(A, B)``: the Jacobians of one control step (``n_sub_steps`` physics steps) with respect to the
    state ``(qpos, qvel)`` (2 nv x 2 nv) and the control (2 nv x nu), at the given state and control
    (zero velocity and control by default). Needs ``nq == nv`` (hinge and slide joints only)."""
    if model.nq != model.nv:
        raise ValueError(f"linearise needs nq == nv (no free or ball joints), got nq={model.nq}, nv={model.nv}")
    nv, nu = model.nv, model.nu
    s0 = np.concatenate([np.asarray(qpos, float), np.zeros(nv) if qvel is None else np.asarray(qvel, float)])
    u0 = np.zeros(nu) if ctrl is None else np.asarray(ctrl, float)

    def f(s, u):
        return _step(model, s[:nv], s[nv:], u, n_sub_steps)

    eye_s, eye_u = np.eye(2 * nv), np.eye(nu)
    a = np.stack([(f(s0 + eps * e, u0) - f(s0 - eps * e, u0)) / (2 * eps) for e in eye_s], axis=1)
    b = np.stack([(f(s0, u0 + eps * e) - f(s0, u0 - eps * e)) / (2 * eps) for e in eye_u], axis=1)
    return a, b


def lqr_gain(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The infinite-horizon discrete LQR gain ``K`` (nu x n) of ``s' = A s + B u`` with costs ``Q``, ``R``."""
    import scipy.linalg

    p = scipy.linalg.solve_discrete_are(a, b, q, r)
    return np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)
