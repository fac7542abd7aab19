import mujoco
import pytest

import jarena
from jarena.arenas import dmc
from jarena.building.grammar import ArenaStringError


def test_suite_table_matches_the_domain_modules():
    for name, tasks in dmc.SUITE.items():
        assert tuple(dmc.DOMAINS[name].tasks) == tasks, name
    listed = jarena.list_arenas("benchmark")
    assert "dmc|domain:cartpole,task:swingup" in listed
    assert len([a for a in listed if a.startswith("dmc|")]) == sum(len(t) for t in dmc.SUITE.values())


def test_unknown_domain_and_task_name_the_choices():
    with pytest.raises(ArenaStringError, match="did you mean 'cartpole'"):
        jarena.build_arena("dmc|domain:cartpol")
    with pytest.raises(ArenaStringError, match="swingup"):
        jarena.build_arena("dmc|domain:cartpole,task:swing")


def test_solver_iterations_are_a_build_option():
    fast = jarena.build_arena("dmc|domain:cartpole,task:balance,iterations:1,ls_iterations:4")
    model = fast.dynamics.render.model
    assert (model.opt.iterations, model.opt.ls_iterations) == (1, 4)
    default = jarena.build_arena("dmc|domain:cartpole,task:balance").dynamics.render.model
    assert (default.opt.iterations, default.opt.ls_iterations) == (100, 50)  # the suite's model is untouched
    assert fast.dynamics.timestep == pytest.approx(0.01)
    with pytest.raises(ValueError, match="iterations must be a positive integer"):
        jarena.build_arena("dmc|domain:cartpole,task:balance,iterations:0")
    euler = jarena.build_arena("dmc|domain:cartpole,task:balance,integrator:euler,eulerdamp:false")
    model = euler.dynamics.render.model
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
    assert model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP)
    with pytest.raises(ValueError, match="unknown integrator 'rk5'; MJX runs euler, rk4, implicitfast"):
        jarena.build_arena("dmc|domain:cartpole,task:balance,integrator:rk5")


def test_device_models_asked_for_inside_a_trace_are_concrete():
    """A cached MJX model first requested while tracing must not hold (and later leak) that trace's tracers."""
    import jax

    from jarena.arenas.dmc import common
    common.device_model.cache_clear()
    jax.jit(lambda x: x + common.device_model("pendulum").body_mass.sum())(1.0)
    assert not isinstance(common.device_model("pendulum").body_mass, jax.core.Tracer)
    jax.jit(lambda x: x * common.device_model("pendulum").body_mass.sum())(2.0)  # a second trace reuses it
