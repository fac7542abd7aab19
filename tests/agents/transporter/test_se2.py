"""Planar motions of images: turned crops match quarter turns of the array, yaw bins round trip, and the random
augmentation moves the pick and place pixels with the image content."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena_agents.transporter import se2

_crops = jax.jit(se2.rotated_crops, static_argnums=3)


def test_turned_crops_are_quarter_turns_of_the_window_about_the_pick():
    """Crop pixel (size // 2, size // 2) is the centre; dropping the crop's first row and column leaves the window of
    half-width size // 2 - 1 around it, which a quarter turn of yaw (+x towards +y: columns towards rows) turns as
    ``np.rot90(window, -1)`` (clockwise as the array prints)."""
    image = np.random.default_rng(0).integers(0, 255, (20, 18, 2)).astype(np.float32)
    centre = np.array([9, 8])
    crops = np.asarray(_crops(image, centre, np.array([0, np.pi / 2, -np.pi / 2, np.pi], np.float32), 8))
    window = image[centre[0] - 3:centre[0] + 4, centre[1] - 3:centre[1] + 4]
    assert crops.shape == (4, 8, 8, 2)
    for crop, turns in zip(crops, [0, -1, 1, 2], strict=True):
        np.testing.assert_array_equal(crop[1:, 1:], np.rot90(window, turns))
    # a point one column to the right of the centre (+x) appears one row below it (+y) after a quarter turn
    assert crops[1][4 + 1, 4].tolist() == image[9, 8 + 1].tolist()
    # outside the image reads zeros
    corner = np.asarray(_crops(image, np.array([0, 0]), np.zeros(1, np.float32), 8))[0]
    assert np.all(corner[:4] == 0) and np.all(corner[:, :4] == 0) and np.array_equal(corner[4:, 4:], image[:4, :4])


def test_yaw_bins_round_trip_and_wrap():
    yaws, bins, wrapped = (np.asarray(x) for x in jax.jit(lambda others: (
        se2.bin_yaws(36), se2.yaw_bins(se2.bin_yaws(36), 36), se2.yaw_bins(others, 36)))(
        np.array([-np.pi, np.pi, 0.04, -0.09, 2 * np.pi], np.float32)))
    assert yaws.shape == (36,) and float(np.min(yaws)) >= -np.pi and float(np.max(yaws)) <= np.pi
    np.testing.assert_array_equal(bins, np.arange(36))
    np.testing.assert_array_equal(wrapped, [18, 18, 0, 35, 0])


def test_augmentation_keeps_the_labels_on_the_same_image_content():
    """Two marks of 3 x 3 pixels (around the pick and the place) in a textured image: after random motions each label
    is on its mark, and the motions do move and turn the image. (The pick lands on its own pixel's content, the place
    within a pixel of its own: a nearest-pixel warp moves some pixels by one more or less than their centres.)"""
    rng = np.random.default_rng(1)
    image = np.zeros((40, 24, 2), np.float32)
    image[..., 1] = rng.uniform(0.1, 1.0, (40, 24))  # texture
    points = np.array([[10.0, 5.0], [30.0, 18.0]], np.float32)
    image[9:12, 4:7, 0], image[29:32, 17:20, 0] = 1.0, 2.0
    image[10, 5, 1] = 5.0  # the pick pixel itself

    moved_images, moved_points = jax.jit(jax.vmap(lambda k: se2.augment(k, jnp.asarray(image), jnp.asarray(points))))(
        jax.random.split(jax.random.key(0), 32))
    moved_images, moved_points = np.asarray(moved_images), np.asarray(moved_points).astype(int)
    angles = []
    for picture, (pick, place) in zip(moved_images, moved_points, strict=True):
        assert 0 <= pick[0] < 40 and 0 <= pick[1] < 24 and 0 <= place[0] < 40 and 0 <= place[1] < 24
        assert picture[pick[0], pick[1]].tolist() == [1.0, 5.0] and picture[place[0], place[1], 0] == 2.0
        # the direction between the marks turns with the image
        before, after = points[1] - points[0], (place - pick).astype(np.float32)
        angles.append(np.arctan2(before[0] * after[1] - before[1] * after[0], before @ after))
    assert np.std(angles) > 0.3  # Ravens' rotations: N(0, pi / 3)
    assert not np.array_equal(moved_images[0], image)


def test_a_motion_that_cannot_keep_the_labels_in_the_image_is_none():
    """Labels at the four corners leave no room: the image and the labels stay as they are."""
    image = jnp.arange(30 * 30, dtype=jnp.float32).reshape(30, 30, 1)
    points = jnp.array([[0.0, 0.0], [0.0, 29.0], [29.0, 0.0], [29.0, 29.0]])
    moved, labels = jax.jit(se2.augment)(jax.random.key(3), image, points)
    np.testing.assert_array_equal(moved, image)
    np.testing.assert_array_equal(labels, points)


# (crop (20, 20), offset (2,)): the window of size 20 around ``centre`` turned by ``yaw``, and ``offset`` turned
_turned = jax.jit(lambda image, centre, offset, yaw: (se2.rotated_crops(image, centre, yaw[None], 20)[0, ..., 0],
                                                      se2.rotate(offset, yaw)))


@pytest.mark.parametrize("yaw", [0.3, -2.0])
def test_a_crop_turns_with_the_points_it_shows(yaw):
    """A marked pixel at an offset from the centre appears in the crop turned by ``yaw`` at the turned offset."""
    image = np.zeros((31, 31, 1), np.float32)
    centre, offset = np.array([15, 15]), np.array([4.0, -6.0])
    image[centre[0] + 4, centre[1] - 6] = 1.0
    crop, turned = _turned(image, centre, offset, np.float32(yaw))
    crop, expected = np.asarray(crop), np.round(np.asarray(turned)).astype(int) + 10
    assert crop[expected[0], expected[1]] == 1.0
