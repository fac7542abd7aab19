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
