"""Dynamics from a MuJoCo model, stepped by MJX (MuJoCo in JAX).

The physics state is an ``mjx.Data``. One ``step`` is one *control* step: the control is written to
``data.ctrl`` and held for ``substeps`` physics steps of ``model.opt.timestep`` seconds each.

Steps follow dm_control's convention: after a step, position- and velocity-dependent quantities
(``xpos``, ``xmat``, ``site_xpos``, sensors, contacts...) agree with the new ``qpos``/``qvel``, so tasks
and sensors read a consistent state. Each physics step runs the second half of MuJoCo's pipeline
(actuation, acceleration, constraint solve, integration) and then the first half for the new state
(kinematics, collisions, velocity terms): the same work as one ``mjx.step``, in a different order.

Physical parameters live in :class:`MjxParams` (scales applied to the model inside ``step``), so users
vmap over them for domain randomisation per episode.

The constraint solver's line search runs as a ``lax.while_loop`` (:func:`while_line_search`): MJX writes it as a
``lax.scan`` of ``ls_iterations`` steps that idle once it has converged, so that reverse-mode gradients flow through
it, and under ``vmap`` an idle step costs as much as a working one. The while loop stops when the batch's slowest
search has converged, and also, as C MuJoCo's search does, once it is at a minimum it cannot improve on in float32
(:func:`_search_loop`): the same states as MJX's scan to the bit on most models, within float32 rounding on the
others, in less time (16 arenas on 2 CPU cores: 2.42x the env-steps/s for walker, 5.13x cheetah, 1.72x humanoid;
``benchmarks/mjx_throughput.py``, variant ``ours-scan``). ``differentiable=True`` keeps MJX's scan, for gradients
through the physics.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
from collections.abc import Callable, Iterator

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct
from mujoco import mjx
from mujoco.mjx._src import solver as mjx_solver

from jarena.core import faults
from jarena.core.dynamics import Dynamics
from jarena.core.spec import Box
from jarena.core.tree import as_float32


@struct.dataclass
class MjxParams:
    """Scales of physical constants (1 = the model's own values); vmap over them to randomise.

    Attributes:
      mass_scale: multiplies every body's mass and rotational inertia (uniform density change).
      friction_scale: multiplies every geom's sliding, torsional and rolling friction.
      damping_scale: multiplies every degree of freedom's joint damping.
      gain_scale: multiplies every actuator's gain (and the matching bias terms of position and
        velocity servos), i.e. the force per unit of control.
    """

    mass_scale: jax.Array = 1.0
    friction_scale: jax.Array = 1.0
    damping_scale: jax.Array = 1.0
    gain_scale: jax.Array = 1.0


def apply_params(model: mjx.Model, params: MjxParams) -> mjx.Model:
    """``model`` with ``params``' scales applied (traceable; batched params give a batched model)."""
    return model.replace(
        body_mass=model.body_mass * params.mass_scale,
        body_inertia=model.body_inertia * params.mass_scale,
        geom_friction=model.geom_friction * params.friction_scale,
        dof_damping=model.dof_damping * params.damping_scale,
        actuator_gainprm=model.actuator_gainprm.at[:, 0].multiply(params.gain_scale),
        actuator_biasprm=model.actuator_biasprm.at[:, 1:3].multiply(params.gain_scale),
    )


_LINE_SEARCH_LOCK = threading.RLock()


def _search_loop(cond_fun, body_fun, init_val, max_iter, flat_start_exit: bool = True):
    """MJX's bounded line-search loop (``solver._while_loop_scan``: ``body_fun`` while ``cond_fun``, at most
    ``max_iter`` times) as a ``lax.while_loop``, returning the final value and the steps taken.

    One exit is added, C MuJoCo's "initial convergence" that MJX's float32 search lacks: the search stops once an end
    of its bracket is flat (its slope under the search's own acceptance tolerance) while neither end costs less than
    the start. On a convex line cost a flat end is the minimum, so nothing lower remains but float32 rounding; MJX
    would halve the bracket until it collapses (about 24 steps, one search in ten on the suite's walker) and then,
    having found no lower cost, not move, as the search stopped here does not. Skipped (MJX's iterations exactly) if
    this MJX version's search names its tolerance or start point otherwise, or with ``flat_start_exit`` false.
    """
    converged_at_start = _converged_at_start(cond_fun) if flat_start_exit else None

    def cond(carry):
        go = (carry[1] < max_iter) & cond_fun(carry[0])
        return go if converged_at_start is None else go & ~converged_at_start(carry[0])

    def body(carry):
        return body_fun(carry[0]), carry[1] + 1

    return jax.lax.while_loop(cond, body, (init_val, jnp.zeros((), jnp.int32)))


def _converged_at_start(cond_fun) -> Callable | None:
    """From MJX's line-search condition (a closure over the start point ``p0`` and the acceptance tolerance
    ``gtol_accept``): ``ctx -> bool``, an end of the bracket flat and neither end below the start's cost; None when
    the closure does not hold both."""
    names = getattr(getattr(cond_fun, "__code__", None), "co_freevars", ())
    cells = dict(zip(names, (cell.cell_contents for cell in (cond_fun.__closure__ or ())), strict=False))
    start, tolerance = cells.get("p0"), cells.get("gtol_accept")
    if start is None or tolerance is None or not hasattr(start, "cost"):
        return None

    def converged(ctx) -> jax.Array:
        lo, hi = ctx.lo, ctx.hi
        flat = (jnp.abs(lo.deriv_0) < tolerance) | (jnp.abs(hi.deriv_0) < tolerance)
        return flat & (lo.cost >= start.cost) & (hi.cost >= start.cost)

    return converged


def _while_loop(cond_fun, body_fun, init_val, max_iter):
    """:func:`_search_loop`'s final value: what replaces ``solver._while_loop_scan``."""
    return _search_loop(cond_fun, body_fun, init_val, max_iter)[0]


@contextlib.contextmanager
def while_line_search() -> Iterator[None]:
    """While tracing inside it, MJX's constraint solver runs its line search as a ``lax.while_loop`` instead of a
    fixed-length ``lax.scan`` (:func:`_search_loop`: the same states, to the bit or within float32 rounding; not
    reverse-mode differentiable). A no-op if this MJX version names its loop otherwise."""
    if not hasattr(mjx_solver, "_while_loop_scan"):
        yield
        return
    with _LINE_SEARCH_LOCK:
        saved = mjx_solver._while_loop_scan
        mjx_solver._while_loop_scan = _while_loop
        try:
            yield
        finally:
            mjx_solver._while_loop_scan = saved


def _integrate(m: mjx.Model, d: mjx.Data, differentiable: bool = True) -> mjx.Data:
    """The second half of a physics step from a position/velocity-consistent state (``mj_step2``); with
    ``differentiable`` false the solver's line search is a while loop (:func:`while_line_search`)."""
    d = mjx.fwd_actuation(m, d)
    d = mjx.fwd_acceleration(m, d)
    if d._impl.efc_J.size == 0:  # no constraints: as mjx.forward does
        d = d.replace(qacc=d.qacc_smooth)
    else:
        with contextlib.nullcontext() if differentiable else while_line_search():
            d = mjx.solve(m, d)
        d = mjx.sensor_acc(m, d)
    integrator = mujoco.mjtIntegrator(int(m.opt.integrator))
    if integrator == mujoco.mjtIntegrator.mjINT_EULER:
        return mjx.euler(m, d)
    if integrator == mujoco.mjtIntegrator.mjINT_RK4:
        return mjx.rungekutta4(m, d)
    if integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST:
        return mjx.implicit(m, d)
    raise NotImplementedError(f"MJX does not implement the {integrator.name} integrator")


def _observe_state(m: mjx.Model, d: mjx.Data) -> mjx.Data:
    """The first half of a physics step (``mj_step1``): quantities that depend on qpos and qvel."""
    d = mjx.fwd_position(m, d)
    d = mjx.sensor_pos(m, d)
    d = mjx.fwd_velocity(m, d)
    return mjx.sensor_vel(m, d)


def physics_step(m: mjx.Model, d: mjx.Data) -> mjx.Data:
    """One physics step of ``m.opt.timestep`` seconds from, and to, a consistent state."""
    return _observe_state(m, _integrate(m, d))


#: The two halves of ``physics_step`` for code that must order them as dm_control does around a reset, e.g.
#: a step taken from a state whose kinematics are still those of ``qpos0`` (``mj_step2`` then ``mj_step1``).
integrate = _integrate
observe_state = _observe_state


def control_spec(model: mujoco.MjModel) -> Box:
    """A Box over the actuators' control ranges (unbounded for actuators without ``ctrllimited``)."""
    limited = np.asarray(model.actuator_ctrllimited, bool)
    low = np.where(limited, model.actuator_ctrlrange[:, 0], -np.inf)
    high = np.where(limited, model.actuator_ctrlrange[:, 1], np.inf)
    return Box(low.astype(np.float32), high.astype(np.float32), dtype=jnp.float32)


def mjx_dynamics(model: mujoco.MjModel, substeps: int = 1, name: str = "mjx",
                 render: Callable | None = None, differentiable: bool = False) -> Dynamics:
    """Dynamics of ``model`` on MJX, with a control step of ``substeps`` physics steps.

    ``init`` gives MuJoCo's reset state (``qpos0``, zero velocity) and ``after_reset`` runs
    ``mjx.forward`` after the task placed the initial state, as dm_control's ``reset_context``.
    Controls outside ``ctrlrange`` are clamped by MuJoCo; ``data.ctrl`` keeps the value given.
    ``differentiable``: keep MJX's line search as a scan, so that reverse-mode gradients flow through ``step``
    (default: a while loop, the same states sooner; see the module docstring).
    """
    if substeps < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    try:
        with jax.ensure_compile_time_eval():  # concrete arrays even if built inside a trace
            device_model = mjx.put_model(model)
    except NotImplementedError as e:
        raise NotImplementedError(f"MJX cannot run model {name!r}: {e}") from None

    def init(key, params):
        return mjx.make_data(device_model)

    def after_reset(data, params):
        return mjx.forward(apply_params(device_model, params), data)

    def step(data, control, params):
        m = apply_params(device_model, params)
        data = data.replace(ctrl=jnp.asarray(control, data.ctrl.dtype))
        # substeps x (integrate, observe), computed as integrate, (substeps - 1) x (observe, integrate),
        # observe: the same work, but the loop body is in mjx.step's order, whose contact and constraint
        # arrays are made and used within one iteration; XLA runs that loop faster on GPUs (walker with
        # Playground's options, 10 substeps, H200: 9% more steps/s than a loop of physics_step). The price is
        # compile time, as the peeled stages are compiled twice (walker 12.5 -> 17.5 s); a one-copy form with
        # each stage behind a lax.cond ran slower than both (benchmarks/RESULTS.md, the Control Suite on MJX).
        data = _integrate(m, data, differentiable)
        if substeps > 1:
            data = jax.lax.fori_loop(0, substeps - 1,
                                     lambda _, d: _integrate(m, _observe_state(m, d), differentiable), data)
        return _observe_state(m, data)

    return Dynamics(init=init, step=step, control_spec=control_spec(model),
                    default_params=lambda: as_float32(MjxParams()),
                    timestep=float(model.opt.timestep) * substeps, render=render, name=name,
                    after_reset=after_reset, finite=is_finite)


def model_of(dynamics: Dynamics) -> mujoco.MjModel:
    """The ``mujoco.MjModel`` that MJX ``dynamics`` were built from (kept by its host renderer)."""
    model = getattr(dynamics.render, "model", None)
    if not isinstance(model, mujoco.MjModel):
        raise TypeError(f"dynamics {dynamics.name!r} do not come from a MuJoCo model (built by mjx_dynamics "
                        "with render=renderer_for(model))")
    return model


def is_finite(data: mjx.Data) -> jax.Array:
    """bool: ``qpos``, ``qvel`` and ``act`` are finite. A NaN or infinity anywhere in a step (control,
    forces, constraint solve, ``qacc``) reaches them through the integrator within that step, so these few
    arrays stand for all of ``mjx.Data`` at the cost of three small reductions."""
    return faults.all_finite((data.qpos, data.qvel, data.act))


@dataclasses.dataclass(frozen=True)
class Names:
    """Name -> index lookups in a MuJoCo model, resolved at build time (static Python ints).

    Unknown names raise a ``KeyError`` that lists the model's names of that kind.
    """

    model: mujoco.MjModel

    def _id(self, kind: mujoco.mjtObj, name: str) -> int:
        i = mujoco.mj_name2id(self.model, kind, name)
        if i < 0:
            count = {mujoco.mjtObj.mjOBJ_BODY: self.model.nbody, mujoco.mjtObj.mjOBJ_JOINT: self.model.njnt,
                     mujoco.mjtObj.mjOBJ_GEOM: self.model.ngeom, mujoco.mjtObj.mjOBJ_SITE: self.model.nsite,
                     mujoco.mjtObj.mjOBJ_ACTUATOR: self.model.nu, mujoco.mjtObj.mjOBJ_SENSOR: self.model.nsensor
                     }.get(kind, 0)
            valid = [mujoco.mj_id2name(self.model, kind, j) for j in range(count)]
            raise KeyError(f"model has no {kind.name[6:].lower()} named {name!r}; it has {valid}")
        return i

    def body(self, name: str) -> int:
        return self._id(mujoco.mjtObj.mjOBJ_BODY, name)

    def geom(self, name: str) -> int:
        return self._id(mujoco.mjtObj.mjOBJ_GEOM, name)

    def site(self, name: str) -> int:
        return self._id(mujoco.mjtObj.mjOBJ_SITE, name)

    def joint(self, name: str) -> int:
        return self._id(mujoco.mjtObj.mjOBJ_JOINT, name)

    def qpos(self, joint: str) -> int:
        """Address of ``joint``'s first coordinate in ``qpos``."""
        return int(self.model.jnt_qposadr[self.joint(joint)])

    def qvel(self, joint: str) -> int:
        """Address of ``joint``'s first degree of freedom in ``qvel``."""
        return int(self.model.jnt_dofadr[self.joint(joint)])

    def sensor(self, name: str) -> slice:
        """Slice of ``sensordata`` holding sensor ``name``."""
        i = self._id(mujoco.mjtObj.mjOBJ_SENSOR, name)
        start = int(self.model.sensor_adr[i])
        return slice(start, start + int(self.model.sensor_dim[i]))
