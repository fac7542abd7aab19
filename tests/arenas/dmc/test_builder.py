import jax
import jax.numpy as jnp
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


def test_timestep_and_contact_culling_are_build_options():
    from mujoco import mjx
    suite = jarena.build_arena("dmc|domain:walker,task:walk")
    fast = jarena.build_arena("dmc|domain:walker,task:walk,timestep:0.005,max_contact_points:4,max_geom_pairs:2")
    model = fast.dynamics.render.model
    assert model.opt.timestep == pytest.approx(0.005)
    assert fast.dynamics.timestep == pytest.approx(suite.dynamics.timestep) == pytest.approx(0.025)
    # MJX sizes the contact arrays from the culling numerics: fewer contact slots per step
    full_slots = mjx.make_data(suite.dynamics.render.model).contact.dist.shape[0]
    culled_slots = mjx.make_data(model).contact.dist.shape[0]
    assert culled_slots < full_slots
    # stepping: 5 physics steps of 5 ms per 25 ms control step instead of 10 of 2.5 ms
    import jax
    state, _ = jax.jit(fast.reset)(jax.random.key(0))
    stepped, _ = jax.jit(fast.step)(state, jax.numpy.zeros(fast.spec.action.shape))
    assert float(stepped.physics.time) == pytest.approx(0.025)
    with pytest.raises(ValueError, match="timestep 0.01 s must divide the control timestep 0.025 s"):
        jarena.build_arena("dmc|domain:walker,task:walk,timestep:0.01")
    with pytest.raises(ValueError, match="max_contact_points must be a positive integer"):
        jarena.build_arena("dmc|domain:walker,task:walk,max_contact_points:0")


def test_device_models_asked_for_inside_a_trace_are_concrete():
    """A cached MJX model first requested while tracing must not hold (and later leak) that trace's tracers."""
    import jax

    from jarena.arenas.dmc import common
    common.device_model.cache_clear()
    jax.jit(lambda x: x + common.device_model("pendulum").body_mass.sum())(1.0)
    assert not isinstance(common.device_model("pendulum").body_mass, jax.core.Tracer)
    jax.jit(lambda x: x * common.device_model("pendulum").body_mass.sum())(2.0)  # a second trace reuses it


@pytest.mark.parametrize("domain", sorted(dmc.SUITE))
def test_resets_fit_the_arenas_model_under_contact_culling(domain):
    """Task initializers that simulate (cheetah's settling) or test collisions on the suite's model must
    return physics shaped as the arena's own (culled) model's, or batches cannot mix stepped and reset
    arenas (traced only: ``jax.eval_shape``)."""
    import jax

    arena = jarena.build_arena(f"dmc|domain:{domain},max_contact_points:2,max_geom_pairs:1")
    state, _ = jax.eval_shape(arena.reset, jax.random.key(0))
    stepped, _ = jax.eval_shape(arena.step, state, arena.action_spec.zeros())  # (spec would trace a reset)
    assert jax.tree.structure(state) == jax.tree.structure(stepped)
    for a, b in zip(jax.tree.leaves(state), jax.tree.leaves(stepped), strict=True):
        assert (a.shape, a.dtype) == (b.shape, b.dtype)


def test_simulation_options_apply_to_each_tasks_own_model():
    """finger's tasks have their own models (spin lowers the hinge damping; turn tasks size the target):
    options must change the chosen task's model, not replace it with another task's or the bare suite's."""
    import numpy as np

    for task, damping, target_size in (("spin", 0.03, 0.03), ("turn_hard", None, 0.03), ("turn_easy", None, 0.07)):
        model = jarena.build_arena(f"dmc|domain:finger,task:{task},iterations:3").dynamics.render.model
        plain = jarena.build_arena(f"dmc|domain:finger,task:{task}").dynamics.render.model
        assert model.opt.iterations == 3 and plain.opt.iterations == 200  # finger.xml sets 200
        hinge = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "hinge")
        np.testing.assert_allclose(model.dof_damping, plain.dof_damping)
        if damping is not None:
            assert model.dof_damping[model.jnt_dofadr[hinge]] == pytest.approx(damping)
        target = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "target")
        assert model.site_size[target, 0] == pytest.approx(target_size)


def test_auto_reset_is_a_build_option_and_suite_domains_default_to_lazy():
    """dmc arenas reset lazily (fresh episodes, computed only when one ends); ``auto_reset:repeat`` stores
    the first episode in the state and steps without tracing the reset (structure checked by eval_shape)."""
    import jax
    import jax.numpy as jnp

    assert jarena.build_arena("dmc|domain:cheetah,task:run").auto_reset == "lazy"
    arena = jarena.build_arena("dmc|domain:cheetah,task:run,auto_reset:repeat")
    assert arena.auto_reset == "repeat"
    states, _ = jax.eval_shape(lambda: jarena.batch_reset(arena, jax.random.key(0), 3))
    assert states.start is not None and states.start[0].physics.qpos.shape == (3, arena.dynamics.render.model.nq)
    stepped, info = jax.eval_shape(lambda s: jarena.batch_step(arena, s, jnp.zeros((3, 6))), states)
    assert jax.tree_util.tree_structure(stepped) == jax.tree_util.tree_structure(states)
    with pytest.raises(ArenaStringError, match="unknown auto_reset 'sometimes'"):
        jarena.build_arena("dmc|domain:cheetah,task:run,auto_reset:sometimes")


def test_differentiable_is_a_build_option():
    """``differentiable:true`` reaches the dynamics (MJX's line-search scan, a cond in each of its steps, instead of
    the default while loop); a value other than true or false is refused, naming the choices."""
    arenas = [jarena.build_arena(f"dmc|domain:walker,task:walk{extra}") for extra in ("", ",differentiable:true")]
    programs = []
    for arena in arenas:
        dynamics, params = arena.dynamics, arena.default_params().dynamics
        data = dynamics.init(jax.random.key(0), params)
        programs.append(str(jax.make_jaxpr(lambda d, dyn=dynamics, p=params: dyn.step(
            d, jnp.zeros(dyn.control_spec.shape), p))(data)))
    assert programs[0].count("cond[") < programs[1].count("cond[")
    with pytest.raises(ValueError, match="differentiable must be true or false, got 3"):
        jarena.build_arena("dmc|domain:walker,task:walk,differentiable:3")
