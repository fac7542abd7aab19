"""The JAX camera against MuJoCo's own renderer (``mujoco.Renderer``, EGL) on the same states.

For each domain, random states are set in MuJoCo (``mj_forward``) and put on MJX; both renderers draw camera 0
at 64 x 64. Issue 18's bars: pixels agree on whether they hit geometry on >= 97% of the image, where both hit the
depth error is < 1 cm at the median and < 5 cm at the 99th percentile, and the object seen agrees on >= 95%.
"""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

import jarena  # noqa: F401  (chooses the headless GL backend before mujoco renders)
from jarena.arenas.dmc import SUITE, common
from jarena.arenas.mjx import camera
from jarena.arenas.mjx.dynamics import model_of

SIZE = 64


def random_state(model, seed):
    """An ``MjData`` of ``model`` at random joint positions, forwarded: hinges move by about 0.4 rad, slides by
    5 cm (so a body's camera stays above the floor), free bodies 0.5 m sideways, quaternions normalised."""
    rng = np.random.default_rng(seed)
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0 + rng.normal(size=model.nq) * 0.4
    for j in range(model.njnt):
        adr = model.jnt_qposadr[j]
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE:
            data.qpos[adr] = model.qpos0[adr] + rng.normal() * 0.05
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            data.qpos[adr + 2] = model.qpos0[adr + 2]
            data.qpos[adr:adr + 2] = rng.normal(size=2) * 0.5
            data.qpos[adr + 3:adr + 7] /= np.linalg.norm(data.qpos[adr + 3:adr + 7])
        elif model.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
            data.qpos[adr:adr + 4] /= np.linalg.norm(data.qpos[adr:adr + 4])
    mujoco.mj_forward(model, data)
    return data


def mujoco_frame(renderer, data, cam):
    renderer.update_scene(data, camera=cam)
    rgb = renderer.render().copy()
    renderer.enable_depth_rendering()
    renderer.update_scene(data, camera=cam)
    depth = renderer.render().copy()
    renderer.disable_depth_rendering()
    renderer.enable_segmentation_rendering()
    renderer.update_scene(data, camera=cam)
    segmentation = renderer.render().copy()
    renderer.disable_segmentation_rendering()
    return rgb, depth, segmentation


_render = jax.jit(camera.render, static_argnums=(0, 2, 3, 4))


def compare(renderer, scene, model, data, cam, height=SIZE, width=SIZE):
    """Both renderers' pictures of ``data`` from ``cam`` and how they agree.

    Returns ``(rgb, segmentation, frame, hits, errors, objects)``: MuJoCo's colour and segmentation, our frame,
    the fraction of pixels on which both agree whether geometry is hit, the depth errors (metres) where both hit,
    and the fraction of pixels that see the same object.
    """
    rgb, depth, segmentation = mujoco_frame(renderer, data, cam)
    frame = jax.device_get(_render(scene, mjx.put_data(model, data), cam, height, width))
    hit_ours, hit_theirs = frame.depth < scene.far * 0.999, depth < scene.far * 0.999
    errors = np.abs(frame.depth - depth)[hit_ours & hit_theirs]
    objects = np.all(frame.segmentation == segmentation, axis=-1).mean()
    return rgb, segmentation, frame, (hit_ours == hit_theirs).mean(), errors, objects


@pytest.mark.parametrize("domain", ["cartpole", "walker", "cheetah", "finger", "humanoid"])
def test_geometry_matches_mujocos_renderer(domain):
    model = common.load_model(domain)
    scene = camera.scene_of(model)
    renderer = mujoco.Renderer(model, SIZE, SIZE)
    try:
        for seed in range(3):
            data = random_state(model, seed)
            rgb, segmentation, frame, hits, error, objects = compare(renderer, scene, model, data, 0)
            assert (segmentation[..., 0] > 0).mean() > 0.01  # the view shows more than the floor (geom 0)
            assert hits >= 0.97
            assert np.median(error) < 0.01 and np.percentile(error, 99) < 0.05, (np.median(error), error.max())
            assert objects >= 0.95
            assert frame.rgb.dtype == np.uint8 and frame.rgb.shape == (SIZE, SIZE, 3)
            # the picture itself: the body's pixels are its colour, warm against the blue-grey floor and sky,
            # as in MuJoCo's picture
            body = (frame.segmentation[..., 1] == camera.GEOM) & (frame.segmentation[..., 0] > 0)
            if body.sum() > 20:
                ours, theirs = frame.rgb[body].astype(int), rgb[body].astype(int)
                assert ours[:, 0].mean() > ours[:, 2].mean() and theirs[:, 0].mean() > theirs[:, 2].mean()
    finally:
        renderer.close()


def test_sites_and_a_tracking_camera_match():
    """Finger's target and tip sites are drawn (object type SITE); walker's camera 1 tracks the torso."""
    for domain, cam in (("finger", 0), ("walker", 1)):
        model = common.load_model(domain)
        scene = camera.scene_of(model)
        renderer = mujoco.Renderer(model, SIZE, SIZE)
        try:
            _, _, frame, _, _, objects = compare(renderer, scene, model, random_state(model, 7), cam)
        finally:
            renderer.close()
        assert objects >= 0.95
        if domain == "finger":
            assert (frame.segmentation[..., 1] == camera.SITE).sum() > 5


def test_non_square_images_and_camera_names():
    model = common.load_model("cartpole")
    scene = camera.scene_of(model)
    data = random_state(model, 1)
    cam = scene.camera("lookatcart")
    assert cam == 1
    renderer = mujoco.Renderer(model, 48, 80)
    try:
        _, _, frame, _, _, objects = compare(renderer, scene, model, data, cam, 48, 80)
    finally:
        renderer.close()
    assert frame.depth.shape == (48, 80)
    assert objects >= 0.95
    with pytest.raises(ValueError, match=r"no camera named 'top'; its cameras: 0: fixed, 1: lookatcart"):
        scene.camera("top")
    with pytest.raises(ValueError, match="camera must be a model camera's name or id; got 5"):
        scene.camera(5)
    with pytest.raises(ValueError, match=r"render: camera must be an id in \[0, 2\)"):
        camera.render(scene, mjx.put_data(model, data), 2, 8, 8)


MESHES = """
<mujoco>
  <asset>
    <mesh name="tet" vertex="0 0 0 1 0 0 0 1 0 0 0 1" scale="0.4 0.4 0.4"/>
    <mesh name="gem" vertex="0.3 0 0  -0.3 0 0  0 0.2 0  0 -0.2 0  0 0 0.25  0 0 -0.25  0.1 0.1 0.1"/>
  </asset>
  <worldbody>
    <light pos="0 0 3"/>
    <camera name="above" pos="0.2 -1.6 1.4" xyaxes="1 0 0 0 0.7 0.7"/>
    <geom name="floor" type="plane" size="2 2 0.1" rgba="0.3 0.4 0.5 1"/>
    <body name="a" pos="-0.3 0 0.4"><freejoint/><geom name="rock" type="mesh" mesh="tet" rgba="0.8 0.5 0.2 1"/></body>
    <body name="b" pos="0.35 0.1 0.35"><freejoint/><geom name="gem" type="mesh" mesh="gem" rgba="0.2 0.7 0.3 1"/></body>
    <body name="c" pos="0 0.3 0.2"><freejoint/><geom name="ball" type="sphere" size="0.1"/></body>
  </worldbody>
</mujoco>"""


def test_meshes_match_mujocos_renderer():
    model = mujoco.MjModel.from_xml_string(MESHES)
    scene = camera.scene_of(model)
    assert [len(m) for m in scene.meshes] == [4, 10]  # the faces of the tetrahedron and of the gem's hull
    renderer = mujoco.Renderer(model, SIZE, SIZE)
    try:
        for seed in range(3):
            data = random_state(model, seed)
            _, segmentation, frame, _, error, objects = compare(renderer, scene, model, data, 0)
            assert np.isin(segmentation[..., 0], (1, 2)).sum() > 50  # the meshes are in view
            assert np.median(error) < 0.01
            assert objects >= 0.97
            rock = frame.rgb[frame.segmentation[..., 0] == 1].astype(int)
            assert rock[:, 0].mean() > rock[:, 2].mean() + 40  # shaded in its orange, not black (normals face out)
    finally:
        renderer.close()


def test_height_fields_are_named_as_not_drawn_yet():
    model = mujoco.MjModel.from_xml_string("""
        <mujoco><asset><hfield name="h" nrow="2" ncol="2" size="1 1 0.1 0.1"/></asset>
        <worldbody><camera name="c" pos="0 0 3"/><geom name="land" type="hfield" hfield="h"/></worldbody></mujoco>""")
    with pytest.raises(NotImplementedError, match=r"cannot draw geom 'land' \(hfield\) yet; it draws plane, sphere"):
        camera.scene_of(model)


def test_render_is_pure_and_batches():
    """Under vmap each state renders as alone; jit does not retrace for new states."""
    model = common.load_model("cartpole")
    scene = camera.scene_of(model)
    states = [mjx.put_data(model, random_state(model, s)) for s in range(3)]
    batch = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *states)
    render = jax.jit(jax.vmap(lambda d: camera.render(scene, d, 0, 24, 24)))
    frames = jax.device_get(render(batch))
    for i, state in enumerate(states):
        one = jax.device_get(_render(scene, state, 0, 24, 24))
        np.testing.assert_array_equal(frames.segmentation[i], one.segmentation)
        np.testing.assert_allclose(frames.depth[i], one.depth, rtol=1e-5)
        assert np.mean(np.abs(frames.rgb[i].astype(int) - one.rgb.astype(int)) > 1) < 0.01
    assert not np.array_equal(frames.depth[0], frames.depth[1])
    traced = render._cache_size()
    render(jax.tree_util.tree_map(lambda x: x[::-1], batch))
    assert render._cache_size() == traced


@pytest.mark.parametrize("domain", sorted(SUITE))
def test_every_suite_domain_and_camera_matches(domain):
    """Every camera of every suite domain (egocentric cameras inside a head included: front faces only and the
    near plane, as MuJoCo's renderer), one random state each."""
    model = model_of(jarena.build_arena(f"dmc|domain:{domain},task:{SUITE[domain][0]}").dynamics)
    scene = camera.scene_of(model)
    data = random_state(model, 3)
    renderer = mujoco.Renderer(model, 32, 32)
    try:
        for cam in range(model.ncam):
            _, _, _, hits, error, objects = compare(renderer, scene, model, data, cam, 32, 32)
            assert hits >= 0.97, cam
            assert np.median(error) < 0.01, cam
            assert objects >= 0.95, cam
    finally:
        renderer.close()
