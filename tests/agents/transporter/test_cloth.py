"""The transporter agent on the cloth arenas' pixel pick-and-place: its pixels are the cloth camera's normalised image
points (u, v) both ways, its height channel is the camera's depth as height above the floor, its augmentation moves
the labels with the cloth's image, and a tiny transporter learns demonstrations stored in the cloth's layout and acts
in the arena's action spec, the same at any batch size.

The demonstrations are synthetic cloth scenes written in the arena's dataset layout (collecting oracle episodes
compiles the cloth's physics, some 20 s of CPU): a patch of cloth with a folded corner to pick and pull out.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.arenas.cloth import camera
from jarena.arenas.cloth.mesh import ClothMesh
from jarena.core.arena import ArenaSpec
from jarena.core.spec import Box, Dict
from jarena.data import TrajectoryDataset, configs_for
from jarena_agents.config import ConfigError
from jarena_agents.transporter import data, se2
from jarena_agents.transporter import layout as layout_lib
from jarena_agents.transporter.networks import raw_input
from tests.agents.transporter.scenes import infos

R = 32  # the tests' camera resolution
CLOTH = f"cloth|particles:8,resolution:{R},horizon:3,initial:flat"
TINY = dict(widths=(8,), head=8, crop=8, rotations=1, learning_rate=3e-3, augment=False)
UPDATES = 150
FLOOR, FRONT, BACK = (56, 56, 59), (237, 158, 61), (69, 135, 209)  # the cloth camera's colours, roughly


@pytest.fixture(scope="module")
def arena():
    return jarena.build_arena(CLOTH)


def test_pixels_and_image_points_round_trip_on_the_cloth_camera(arena):
    layout = layout_lib.layout_of(arena.spec)
    assert layout == layout_lib.Layout(shape=(R, R), frame="image_points", height_key="depth", table_depth=1.5)
    pixels = np.stack(np.meshgrid(np.arange(R), np.arange(R), indexing="ij"), -1).astype(np.float32)  # (R, R, 2)
    points = layout_lib.pixels_to_points(pixels, layout.shape)
    # a pixel's point is its centre in the camera's coordinates, which the camera maps back onto that pixel
    np.testing.assert_allclose(points, np.asarray(camera.pixel_uv(R)), atol=1e-6)
    np.testing.assert_allclose(np.asarray(camera.uv_to_pixel(points, R)), pixels[..., ::-1] + 0.5, atol=1e-5)
    np.testing.assert_array_equal(layout_lib.points_to_pixels(points, layout.shape), pixels)

    # actions both ways, in numpy and in jax alike: pixels -> points -> the same pixels; points -> pixels -> points
    rng = np.random.default_rng(0)
    moves = np.concatenate([rng.integers(0, R, (64, 4)), np.zeros((64, 1))], -1).astype(np.float32)
    arena_actions = layout_lib.to_arena_action(moves, layout)
    assert arena_actions.shape == (64, 4) and bool(np.all(np.abs(arena_actions) < 1))
    np.testing.assert_array_equal(layout_lib.from_arena_action(arena_actions, layout), moves)
    np.testing.assert_array_equal(np.asarray(jax.jit(lambda a: layout_lib.to_arena_action(a, layout))(moves)),
                                  arena_actions)
    demonstrated = rng.uniform(-1, 1, (64, 4)).astype(np.float32)
    back = layout_lib.to_arena_action(layout_lib.from_arena_action(demonstrated, layout), layout)
    np.testing.assert_allclose(back, demonstrated, atol=1e-6)
    labels = np.round(layout_lib.from_arena_action(demonstrated, layout)[:, :4])  # the nearest pixel centres
    centres = layout_lib.to_arena_action(np.concatenate([labels, np.zeros((64, 1))], -1), layout)
    assert np.abs(centres - demonstrated).max() <= 1 / R + 1e-6


@pytest.fixture(scope="module")
def rendered():
    """A flat 8 x 8 cloth lying 3 cm above the floor, off the camera's axis (its centre at x 0.1, y -0.15 m), as the
    cloth camera renders it at R x R, and its four corners, world x-y-z (4, 3)."""
    mesh = ClothMesh.of_size(0.4, 0.4, cols=8)
    positions = np.asarray(mesh.rest_positions, np.float32) + np.array([0.1, -0.15, 0.0], np.float32)
    positions[:, 2] = 0.03
    image = jax.jit(camera.render, static_argnums=(1, 3))(positions, mesh, camera.CameraParams(), R)
    return {k: np.asarray(v) for k, v in image.items()}, positions[np.asarray(mesh.corners)]


def test_the_height_channel_is_the_depth_as_height_above_the_floor(arena, rendered):
    image, corners = rendered
    layout = layout_lib.layout_of(arena.spec)
    height = layout_lib.height_map(image, layout)
    assert image["mask"].sum() > 20
    np.testing.assert_allclose(height[image["mask"]], 0.03, atol=1e-4)
    np.testing.assert_array_equal(height[~image["mask"]], 0.0)
    np.testing.assert_allclose(np.asarray(layout_lib.height_map({k: jnp.asarray(v) for k, v in image.items()}, layout)),
                               height, atol=1e-7)
    # the corners' image points, as pixels, bound the cloth's pixels (rows grow down the image, towards -y)
    corner_pixels = layout_lib.points_to_pixels(np.asarray(camera.world_to_pixel(corners, camera.CameraParams())),
                                                layout.shape)
    cloth = np.argwhere(image["mask"])
    assert np.all(cloth >= corner_pixels.min(0) - 0.5) and np.all(cloth <= corner_pixels.max(0) + 0.5)
    assert np.all(np.abs(np.percentile(cloth, [0, 100], axis=0) - [corner_pixels.min(0), corner_pixels.max(0)]) <= 1)
    assert cloth[:, 0].mean() > R / 2 + 2 and cloth[:, 1].mean() > R / 2 + 1  # below and right of the centre
    # without a depth image the height channel is zeros; a height map is read as it is
    no_depth = jarena.build_arena(CLOTH + ",depth:false").spec
    np.testing.assert_array_equal(layout_lib.height_map({"rgb": image["rgb"]}, layout_lib.layout_of(no_depth)), 0.0)
    heights = ArenaSpec(observation=Dict(rgb=Box(0, 255, (R, R, 3), np.uint8), height=Box(0.0, 1.0, (R, R))),
                        action=arena.spec.action, name="heights")
    np.testing.assert_array_equal(layout_lib.height_map({"height": height}, layout_lib.layout_of(heights)), height)


def test_augmentation_keeps_the_labels_on_the_cloth_image(arena, rendered):
    """A pull of the cloth's corner outwards, demonstrated as image points: after random motions of the image (a
    seventh channel numbering the pixels) the pick label is on its own pixel, the place label within a pixel of
    its own, and the cloth turns and moves with them."""
    image, corners = rendered
    layout = layout_lib.layout_of(arena.spec)
    grip = corners[0] + 0.2 * (corners.mean(0) - corners[0])  # near the first corner, on the cloth
    pick = np.asarray(camera.world_to_pixel(grip, camera.CameraParams()))
    action = np.concatenate([pick, pick * 1.5]).astype(np.float32)  # pulled outwards
    points = np.round(layout_lib.from_arena_action(action, layout)[:4].reshape(2, 2))
    assert image["mask"][int(points[0, 0]), int(points[0, 1])]
    ids = np.arange(R * R, dtype=np.float32).reshape(R, R, 1)
    picture = np.concatenate([raw_input(image["rgb"], layout_lib.height_map(image, layout)), ids], -1)

    moved_images, moved_points = jax.jit(jax.vmap(lambda k: se2.augment(k, jnp.asarray(picture), jnp.asarray(points))))(
        jax.random.split(jax.random.key(0), 32))
    moved_images, moved_points = np.asarray(moved_images), np.asarray(moved_points).astype(int)
    turns = []
    for moved, (new_pick, new_place) in zip(moved_images, moved_points, strict=True):
        assert np.all((moved_points >= 0) & (moved_points < R))
        np.testing.assert_array_equal(moved[new_pick[0], new_pick[1]], picture[int(points[0, 0]), int(points[0, 1])])
        was = np.divmod(int(moved[new_place[0], new_place[1], 6]), R)
        assert np.abs(np.subtract(was, points[1])).max() <= 1
        assert moved[new_pick[0], new_pick[1], 3] > 0.02  # on the cloth (3 cm up) still
        before, after = points[1] - points[0], (new_place - new_pick).astype(np.float32)
        turns.append(np.arctan2(before[0] * after[1] - before[1] * after[0], before @ after))
    assert np.std(turns) > 0.3 and not np.array_equal(moved_images[0], picture)


def cloth_scenes(count: int, seed: int) -> dict:
    """Synthetic top-down cloth images at R x R in the arena's observation layout (``rgb``, ``depth`` metres from the
    camera 1.5 m up, ``mask``) and their demonstrations, image points (count, 4): a square patch of cloth (5 mm up)
    with one corner folded over (3 x 3 pixels of its back, 1 cm up); the demonstration picks the folded corner's tip
    and pulls it 4 pixels outwards."""
    rng = np.random.default_rng(seed)
    rgb = np.broadcast_to(np.array(FLOOR, np.uint8), (count, R, R, 3)).copy()
    depth = np.full((count, R, R), 1.5, np.float32)
    mask = np.zeros((count, R, R), np.uint8)
    pixels = np.zeros((count, 4), np.float32)
    for i in range(count):
        side = rng.integers(8, 13)
        top, left = rng.integers(5, R - 5 - side, size=2)
        rgb[i, top:top + side, left:left + side], depth[i, top:top + side, left:left + side] = FRONT, 1.495
        mask[i, top:top + side, left:left + side] = 1
        down, right = rng.integers(2, size=2)  # which corner is folded
        tip = np.array([top + down * (side - 1), left + right * (side - 1)])
        rows = slice(tip[0] - 2 * down, tip[0] - 2 * down + 3)
        cols = slice(tip[1] - 2 * right, tip[1] - 2 * right + 3)
        rgb[i, rows, cols], depth[i, rows, cols] = BACK, 1.49
        pixels[i] = [*tip, *(tip + 4 * (2 * np.array([down, right]) - 1))]
    layout = layout_lib.Layout(shape=(R, R), frame="image_points")
    return dict(rgb=rgb, depth=depth, mask=mask, action=layout_lib.to_arena_action(
        np.concatenate([pixels, np.zeros((count, 1), np.float32)], -1), layout))


@pytest.fixture(scope="module")
def trained(arena, tmp_path_factory):
    """A tiny transporter trained through ``init_training`` on 16 one-action demonstrations written in the arena's
    dataset layout, then acting on the training scenes and 8 new ones (a batch of 24), on three of the new ones
    and on one alone. One compiled program."""
    demos, new = cloth_scenes(16, seed=0), cloth_scenes(8, seed=1)
    path = str(tmp_path_factory.mktemp("cloth") / "demos")
    with TrajectoryDataset(path, "w", **configs_for(arena)) as dataset:
        dataset.add_trajectories([dict(observations={k: np.stack([demos[k][i]] * 2) for k in ("rgb", "depth", "mask")},
                                       actions=demos["action"][i:i + 1]) for i in range(16)])
    agent = jarena_agents.build_agent("transporter", dict(TINY, dataset=path))
    keys = ("rgb", "depth", "mask")
    batches = [infos({k: np.concatenate([demos[k], new[k]]) for k in keys}), infos({k: new[k][:3] for k in keys}),
               infos({k: new[k][2:3] for k in keys})]

    @jax.jit
    def run(key):
        state, metrics = agent.train(agent.init_training(key, arena), arena, UPDATES)
        policy = agent.policy(state, arena.spec)
        actions = [agent.act(policy, info, key)[0] for info in batches]
        return state.data, metrics, actions, jax.vmap(arena.action_spec.contains)(actions[0])

    read, metrics, actions, in_spec = jax.tree_util.tree_map(np.asarray, run(jax.random.key(0)))
    return dict(demos=demos, new=new, read=read, metrics=metrics, actions=actions, in_spec=in_spec, path=path)


def test_demonstrations_are_read_as_pixels_and_heights(arena, trained):
    demos, read = trained["demos"], trained["read"]
    assert read["rgb"].shape == (16, R, R, 3) and read["height"].shape == (16, R, R) and read["action"].shape == (16, 5)
    np.testing.assert_array_equal(read["rgb"], demos["rgb"])
    np.testing.assert_allclose(read["height"][demos["mask"] == 0], 0.0)
    assert np.isclose(read["height"].max(), 0.01, atol=1e-5)
    pixels = read["action"][:, :4]
    np.testing.assert_allclose(pixels, np.round(pixels), atol=1e-5)  # the scenes' pixel centres
    np.testing.assert_array_equal(read["action"][:, 4], 0.0)
    rows, cols = np.round(pixels[:, :2]).astype(int).T
    on_fold = np.all(read["rgb"][np.arange(16), rows, cols] == BACK, -1)
    assert on_fold.all()  # each pick label is on its scene's folded corner
    again = data.read_dataset(trained["path"], arena, layout_lib.layout_of(arena.spec))
    np.testing.assert_array_equal(again["action"], read["action"])


def test_a_tiny_transporter_learns_cloth_demonstrations_and_acts_in_image_points(trained):
    metrics = trained["metrics"]
    assert metrics["loss"].shape == (UPDATES,) and np.all(np.isfinite(metrics["loss"]))
    for name in ("attention_loss", "transport_loss"):
        assert np.mean(metrics[name][-10:]) < 0.1 * np.mean(metrics[name][:10]), name
    both, three, one = trained["actions"]
    assert both.shape == (24, 4) and both.dtype == np.float32 and bool(np.all(trained["in_spec"]))
    # the demonstrated image points themselves: picks and places at the right pixels, in the arena's frame
    np.testing.assert_allclose(both[:16], trained["demos"]["action"], atol=1e-6)
    picks = np.mean(np.all(np.abs(both[16:, :2] - trained["new"]["action"][:, :2]) < 1e-6, -1))
    assert picks >= 0.75, picks  # the folded corner in scenes it never saw
    np.testing.assert_array_equal(three, both[16:19])
    np.testing.assert_array_equal(one, both[18:19])


def test_arenas_and_configs_that_do_not_fit_get_clear_errors(arena):
    agent = jarena_agents.build_agent("transporter", TINY)
    agent.init(jax.random.key(0), arena.spec, 1)  # fits
    with pytest.raises(ConfigError, match="image points, which have no yaw; set rotations: 1 \\(got 4\\)"):
        jarena_agents.build_agent("transporter", dict(TINY, rotations=4)).init(jax.random.key(0), arena.spec, 1)
    with pytest.raises(ConfigError, match="unknown action_frame 'uv'"):
        jarena_agents.build_agent("transporter", dict(TINY, action_frame="uv"))
    with pytest.raises(ConfigError, match="\\(action_frame: pixels\\) with \\(pick_row"):
        jarena_agents.build_agent("transporter", dict(TINY, action_frame="pixels")).init(jax.random.key(0),
                                                                                           arena.spec, 1)
    two = jarena.build_arena(CLOTH + ",action:pixel_pick_and_place(2)")
    with pytest.raises(ConfigError, match="one pick and one place as normalised image points"):
        agent.init(jax.random.key(0), two.spec, 1)
    world = jarena.build_arena(CLOTH + ",action:pick_and_place(1)")
    agent.init(jax.random.key(0), world.spec, 1)  # the spec alone cannot tell; the tool can
    with pytest.raises(ConfigError, match="tool 'pick_and_place\\(1\\)' may not take normalised image points"):
        agent.init_training(jax.random.key(0), world)
