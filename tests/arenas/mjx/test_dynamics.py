import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

from jarena.arenas.mjx.dynamics import MjxParams, mjx_dynamics, physics_step

# A two-link arm over a floor and a box that falls onto it: hinge actuators, contacts, Euler steps.
_XML = """
<mujoco>
  <option timestep="0.005"/>
  <worldbody>
    <geom type="plane" size="2 2 0.1"/>
    <body pos="0 0 1">
      <joint name="shoulder" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.04"/>
      <body pos="0.4 0 0">
        <joint name="elbow" type="hinge" axis="0 1 0" damping="0.1"/>
        <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.04"/>
      </body>
    </body>
    <body pos="0.5 0.5 0.3">
      <freejoint/>
      <geom type="box" size="0.05 0.05 0.05"/>
    </body>
  </worldbody>
  <actuator>
    <motor joint="shoulder" gear="5" ctrlrange="-1 1" ctrllimited="true"/>
    <motor joint="elbow" gear="5" ctrlrange="-1 1" ctrllimited="true"/>
  </actuator>
</mujoco>
"""


@pytest.mark.parametrize("substeps", [1, 4])
def test_a_control_step_is_substeps_physics_steps_ending_consistent(substeps):
    """One control step equals ``substeps`` calls of ``physics_step`` (whatever the loop's arrangement), matches
    MuJoCo's ``mj_step`` repeated, and leaves kinematics consistent with the new positions."""
    model = mujoco.MjModel.from_xml_string(_XML)
    dynamics = mjx_dynamics(model, substeps)
    params = jax.tree.map(jnp.asarray, MjxParams())
    m = mjx.put_model(model)
    data = jax.jit(lambda k: dynamics.after_reset(dynamics.init(k, params), params))(jax.random.key(0))
    control = jnp.array([0.7, -0.4], jnp.float32)

    @jax.jit
    def ours(d):
        return dynamics.step(d, control, params)

    @jax.jit
    def reference(d):
        d = d.replace(ctrl=control)
        for _ in range(substeps):
            d = physics_step(m, d)
        return d

    mj = mujoco.MjData(model)
    mujoco.mj_forward(model, mj)
    for _ in range(60 // substeps):  # the box lands on the floor: contacts
        data, expected = ours(data), reference(data)
        for name in ("qpos", "qvel", "xpos", "qacc_warmstart", "time"):
            np.testing.assert_allclose(getattr(data, name), getattr(expected, name), rtol=1e-5, atol=1e-5,
                                       err_msg=name)
        mj.ctrl[:] = control
        for _ in range(substeps):
            mujoco.mj_step(model, mj)
    assert mj.ncon > 0
    np.testing.assert_allclose(data.qpos, mj.qpos, atol=1e-4)
    np.testing.assert_allclose(data.qvel, mj.qvel, atol=1e-3)
    # kinematics consistent with the new positions, as dm_control's
    np.testing.assert_allclose(data.xpos, jax.jit(mjx.kinematics)(m, data).xpos, atol=1e-6)
    assert float(data.time) == pytest.approx(60 // substeps * substeps * 0.005)


def test_the_while_line_search_steps_a_batch_to_the_same_bits_as_mjx_scan():
    """The default dynamics (line search as a while loop) and ``differentiable=True`` (MJX's fixed-length scan)
    give the same states to the bit, vmapped over arenas whose searches end at different iterations."""
    model = mujoco.MjModel.from_xml_string(_XML)
    params = jax.tree.map(jnp.asarray, MjxParams())
    fast, scanned = mjx_dynamics(model, 2), mjx_dynamics(model, 2, differentiable=True)
    start = jax.jit(jax.vmap(lambda k: fast.after_reset(fast.init(k, params), params)))(jax.random.split(
        jax.random.key(0), 4))
    controls = jax.random.uniform(jax.random.key(1), (40, 4, 2), minval=-1.0, maxval=1.0)

    def rollout(dynamics):
        def body(d, control):
            d = jax.vmap(dynamics.step, in_axes=(0, 0, None))(d, control, params)
            return d, (d.qpos, d.qvel)
        return jax.jit(lambda d: jax.lax.scan(body, d, controls)[1])(start)

    for ours, theirs in zip(rollout(fast), rollout(scanned), strict=True):
        np.testing.assert_array_equal(ours, theirs)
    one = jax.tree.map(lambda x: x[0], start)
    programs = [str(jax.make_jaxpr(lambda d, dyn=dyn: dyn.step(d, controls[0, 0], params))(one))
                for dyn in (fast, scanned)]
    # the two line searches (one per physics step of the loop's two copies): scans with a cond in MJX's form,
    # while loops in ours (the solver's own outer loop is a while loop in both)
    assert [p.count("while[") - programs[1].count("while[") for p in programs] == [2, 0]
    assert [p.count("cond[") for p in programs] == [0, 2]


def test_a_line_search_stops_once_an_end_is_flat_and_nothing_costs_less_than_the_start():
    """The exit the while loop adds to MJX's search: an end of the bracket flat (slope under the search's acceptance
    tolerance ``gtol_accept``) while neither end costs less than the start ``p0`` ends the search at once; with an
    end below the start's cost, or no end flat, MJX's own condition decides."""
    from typing import NamedTuple

    from jarena.arenas.mjx.dynamics import _search_loop

    class Point(NamedTuple):
        cost: jax.Array
        deriv_0: jax.Array

    class Search(NamedTuple):
        lo: Point
        hi: Point
        n: jax.Array

    def point(cost, slope):
        return Point(jnp.float32(cost), jnp.float32(slope))

    p0, gtol_accept = point(5.0, -1.0), jnp.float32(1e-3)

    def cond(ctx):  # in MJX's form, a closure over p0 and gtol_accept; on its own it runs 30 steps
        return (ctx.n < 30) & (p0.cost > 0) & (gtol_accept > 0)

    def steps(lo, hi):
        search = Search(lo, hi, jnp.int32(0))
        return int(_search_loop(cond, lambda c: c._replace(n=c.n + 1), search, 50)[1])

    assert steps(point(5.0, 1e-5), point(5.0, -1.0)) == 0  # flat at the start's cost: stop
    assert steps(point(6.0, 0.5), point(5.0, -1e-4)) == 0  # flat, nothing lower: stop
    assert steps(point(5.0, 1e-5), point(4.9, -1.0)) == 30  # an end below the start: MJX's condition runs on
    assert steps(point(5.0, 0.5), point(5.0, -1.0)) == 30  # no end flat: MJX's condition runs on


def test_the_installed_mjx_line_search_takes_the_flat_start_exit():
    """The exit reads MJX's search condition's closure (``p0``, ``gtol_accept``): it must find both in the MJX
    installed, or the arenas lose its speed (the suite's walker: 2.4x MJX's scan instead of 1.6x) without a sign."""
    import jarena.arenas.mjx.dynamics as dynamics_module

    found = []
    plain = dynamics_module._converged_at_start

    def spy(cond_fun):
        found.append(plain(cond_fun) is not None)
        return plain(cond_fun)

    model = mjx.put_model(mujoco.MjModel.from_xml_string(_XML))
    data = jax.jit(mjx.forward)(model, mjx.make_data(model))
    dynamics_module._converged_at_start = spy
    try:
        with dynamics_module.while_line_search():  # what the arenas' steps trace the solver inside
            jax.make_jaxpr(lambda d: mjx.solve(model, d))(data)
    finally:
        dynamics_module._converged_at_start = plain
    assert found and all(found), found


def test_differentiable_dynamics_pass_gradients_through_a_one_iteration_solver():
    """With one solver iteration (MJX's outer solver loop is a while loop otherwise) and ``differentiable=True``,
    reverse-mode gradients flow through a step with contacts; the default while-loop line search refuses them."""
    model = mujoco.MjModel.from_xml_string(_XML)
    model.opt.iterations = 1
    params = jax.tree.map(jnp.asarray, MjxParams())
    for differentiable in (True, False):
        dynamics = mjx_dynamics(model, 1, differentiable=differentiable)
        data = jax.jit(lambda k: dynamics.after_reset(dynamics.init(k, params), params))(jax.random.key(0))
        rest = jax.jit(lambda d, dynamics=dynamics: dynamics.step(d, jnp.zeros(2), params))  # compiled once
        for _ in range(40):  # the box lands: the step solves contacts
            data = rest(data)

        def speed(control):  # the arm's joint speeds after the step, from a solve with the box's contacts
            return dynamics.step(data, control, params).qvel[:2].sum()

        if differentiable:
            gradient = jax.jit(jax.grad(speed))(jnp.array([0.5, -0.5]))
            assert np.all(np.isfinite(gradient)) and np.any(gradient != 0)
        else:
            with pytest.raises(ValueError, match="Reverse-mode differentiation does not work"):
                jax.grad(speed)(jnp.array([0.5, -0.5]))
