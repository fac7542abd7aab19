"""The numpy canvas and the classic arenas' 2-D renderers: shapes land where the physics puts them."""

import dataclasses

import jax
import numpy as np
import pytest

import jarena
from jarena.render.canvas import Canvas
from jarena.render.classic import draw_acrobot, draw_cartpole, draw_mountain_car, draw_pendulum, draw_point_mass

DOMAINS = ["cartpole", "pendulum", "acrobot", "mountain_car", "point_mass"]


def params(domain):
    return jax.device_get(jarena.build_arena(f"classic|domain:{domain}").default_params().dynamics)


def pixels_of(image, color):
    """(rows, cols) of the pixels of exactly ``color``."""
    return np.nonzero(np.all(image == np.asarray(color, np.uint8), axis=-1))


def centroid(image, color):
    rows, cols = pixels_of(image, color)
    assert rows.size, f"no pixel of colour {color}"
    return rows.mean(), cols.mean()


def test_canvas_primitives_cover_the_right_pixels():
    c = Canvas(200, 100, (0, 2), (0, 1))  # 100 pixels per unit
    assert c.scale == 100
    c.rectangle((1.0, 0.5), (0.5, 0.2), (1, 0, 0))
    assert pixels_of(c.image, (1, 0, 0))[0].size == 50 * 20
    rotated = Canvas(200, 100, (0, 2), (0, 1)).rectangle((1.0, 0.5), (0.5, 0.2), (1, 0, 0), angle=np.pi / 2)
    rows, cols = pixels_of(rotated.image, (1, 0, 0))
    assert np.ptp(rows) + 1 == pytest.approx(50, abs=1) and np.ptp(cols) + 1 == pytest.approx(20, abs=1)
    disk = Canvas(200, 100, (0, 2), (0, 1)).disk((0.5, 0.5), 0.2, (0, 1, 0))
    assert pixels_of(disk.image, (0, 1, 0))[0].size == pytest.approx(np.pi * 20**2, rel=0.02)
    assert centroid(disk.image, (0, 1, 0)) == pytest.approx((50, 50), abs=0.5)  # y up: row 50 is y = 0.5
    line = Canvas(200, 100, (0, 2), (0, 1)).line((0.2, 0.9), (1.8, 0.9), 0.04, (0, 0, 1))
    rows, cols = pixels_of(line.image, (0, 0, 1))
    assert rows.mean() == pytest.approx(10, abs=0.5) and np.ptp(cols) + 1 == pytest.approx(164, abs=1)
    curve = Canvas(200, 100, (0, 2), (0, 1)).graph(lambda x: 0.5 + 0.4 * np.sin(3 * x), 0, 2, 0.01, (9, 9, 9))
    rows, cols = pixels_of(curve.image, (9, 9, 9))
    assert set(cols) == set(range(200))  # no gaps, even where the curve is steep
    off = Canvas(20, 10, (0, 2), (0, 1)).disk((50.0, 50.0), 0.1, (1, 1, 1)).line((5, 5), (6, 6), 0.1, (1, 1, 1))
    assert pixels_of(off.image, (1, 1, 1))[0].size == 0  # shapes outside the view are clipped, no error


@pytest.mark.parametrize("domain", DOMAINS)
def test_classic_arenas_render_their_reset_states(domain):
    arena = jarena.build_arena(f"classic|domain:{domain}")
    state, _ = arena.reset(jax.random.key(0))
    image = arena.dynamics.render(state.physics, arena.default_params().dynamics, width=160, height=100)
    assert image.shape == (100, 160, 3) and image.dtype == np.uint8
    assert image.std() > 5 and len(np.unique(image.reshape(-1, 3), axis=0)) >= 3
    with pytest.raises(ValueError, match="single fixed view; camera must be -1"):
        arena.dynamics.render(state.physics, arena.default_params().dynamics, camera="top")


def test_cartpole_pole_follows_cart_and_angle():
    p = params("cartpole")
    state = jarena.arenas.classic.cartpole.CartPoleState(x=-1.0, x_dot=0.0, theta=0.0, theta_dot=0.0)
    pole = (202, 152, 101)
    left = centroid(draw_cartpole(state, p, width=480, height=320), pole)
    right = centroid(draw_cartpole(dataclasses.replace(state, x=1.0), p, width=480, height=320), pole)
    assert right[1] - left[1] == pytest.approx(2.0 * 100, abs=1)  # 480 px for 4.8 m
    tilted = centroid(draw_cartpole(dataclasses.replace(state, x=-1.0, theta=0.5), p, width=480, height=320), pole)
    assert tilted[1] > left[1] + 20 and tilted[0] > left[0]  # positive theta leans right, and lower
    longer = draw_cartpole(state, dataclasses.replace(p, length=p.length * 2), width=480, height=320)
    assert pixels_of(longer, pole)[0].size > 1.8 * pixels_of(draw_cartpole(state, p, width=480, height=320),
                                                             pole)[0].size


def test_pendulum_acrobot_mountain_car_point_mass_geometry():
    module = jarena.arenas.classic
    red = (204, 77, 77)
    up = centroid(draw_pendulum(module.pendulum.PendulumState(theta=0.0, theta_dot=0.0), params("pendulum")), red)
    down = centroid(draw_pendulum(module.pendulum.PendulumState(theta=np.pi, theta_dot=0.0), params("pendulum")), red)
    left = centroid(draw_pendulum(module.pendulum.PendulumState(theta=np.pi / 2, theta_dot=0.0), params("pendulum")),
                    red)
    assert up[0] < 120 < down[0] and left[1] < 160  # axle at the centre (120, 160); theta counter-clockwise
    cyan = (0, 204, 204)
    hanging = centroid(draw_acrobot(module.acrobot.AcrobotState(0.0, 0.0, 0.0, 0.0), params("acrobot")), cyan)
    raised = centroid(draw_acrobot(module.acrobot.AcrobotState(np.pi, 0.0, 0.0, 0.0), params("acrobot")), cyan)
    assert hanging[0] > 120 > raised[0]
    car = [centroid(draw_mountain_car(module.mountain_car.MountainCarState(position=x, velocity=0.0),
                                      params("mountain_car")), (128, 128, 128)) for x in (-1.0, -0.5, 0.3)]
    assert car[0][1] < car[1][1] < car[2][1] and car[1][0] > car[2][0]  # the valley bottom is near -0.52
    dot = (200, 40, 40)
    at = centroid(draw_point_mass(module.point_mass.PointMassState(position=np.array([0.5, -0.5]),
                                                                   velocity=np.zeros(2)), params("point_mass"),
                                  width=220, height=220), dot)
    assert at == pytest.approx((110 + 50, 110 + 50), abs=1)  # 220 px for 2.2 units; y up
