"""2-D renderers of the classic-control arenas, drawn with numpy after Gymnasium's pictures.

Each is a ``Dynamics.render``: ``(physics, params, *, width, height, camera) -> uint8 (height, width, 3)``
for ONE arena's physics state and dynamics params (host or device arrays). The classic arenas have a
single fixed view, so ``camera`` must be ``-1`` (the default) or ``None``.
"""

from __future__ import annotations

import numpy as np

from jarena.render.canvas import Canvas

BLACK = (0, 0, 0)
WHITE = (255, 255, 255)


def _check_camera(camera, domain: str) -> None:
    if camera not in (-1, None):
        raise ValueError(f"the classic {domain} arena has a single fixed view; camera must be -1 (the default), "
                         f"got {camera!r}")


def _f(x) -> float:
    return float(np.asarray(x))


def draw_cartpole(physics, params, *, width: int = 320, height: int = 240, camera=-1) -> np.ndarray:
    """The cart on its track (x in [-2.4, 2.4] m fills the width) and the pole (length ``2 params.length``)."""
    _check_camera(camera, "cartpole")
    x, theta, length = _f(physics.x), _f(physics.theta), _f(params.length)
    canvas = Canvas(width, height, (-2.4, 2.4), (-0.8, 2.4))
    canvas.line((-2.6, 0.0), (2.6, 0.0), 0.01, BLACK)
    canvas.rectangle((x, 0.0), (0.4, 0.24), BLACK)
    pivot = np.array([x, 0.06])
    tip = pivot + 2 * length * np.array([np.sin(theta), np.cos(theta)])
    canvas.line(pivot, tip, 0.08, (202, 152, 101))
    canvas.disk(pivot, 0.04, (129, 132, 203))
    return canvas.image


def draw_pendulum(physics, params, *, width: int = 320, height: int = 240, camera=-1) -> np.ndarray:
    """The rod (length ``params.l``, theta = 0 upright, counter-clockwise positive) about its axle."""
    _check_camera(camera, "pendulum")
    theta, length = _f(physics.theta), _f(params.l)
    canvas = Canvas(width, height, (-2.2, 2.2), (-2.2, 2.2))
    tip = length * np.array([-np.sin(theta), np.cos(theta)])
    canvas.line((0.0, 0.0), tip, 0.2, (204, 77, 77))
    canvas.disk((0.0, 0.0), 0.05, BLACK)
    return canvas.image


def draw_acrobot(physics, params, *, width: int = 320, height: int = 240, camera=-1) -> np.ndarray:
    """Both links hanging from the pivot (theta1 = 0 straight down) and the goal bar at height 1."""
    _check_camera(camera, "acrobot")
    t1, t2, l1, l2 = _f(physics.theta1), _f(physics.theta2), _f(params.link_length_1), 1.0  # Gymnasium's l2 = 1
    bound = l1 + l2 + 0.2
    canvas = Canvas(width, height, (-bound, bound), (-bound, bound))
    canvas.line((-bound, 1.0), (bound, 1.0), 0.01, BLACK)
    p1 = l1 * np.array([np.sin(t1), -np.cos(t1)])
    p2 = p1 + l2 * np.array([np.sin(t1 + t2), -np.cos(t1 + t2)])
    canvas.line((0.0, 0.0), p1, 0.2, (0, 204, 204))
    canvas.line(p1, p2, 0.2, (0, 204, 204))
    canvas.disk((0.0, 0.0), 0.1, (204, 204, 0))
    canvas.disk(p1, 0.1, (204, 204, 0))
    return canvas.image


def _hill(x):
    return np.sin(3 * x) * 0.45 + 0.55


def draw_mountain_car(physics, params, *, width: int = 320, height: int = 240, camera=-1) -> np.ndarray:
    """The hill ``0.45 sin(3 x) + 0.55``, the car on it and the goal flag at x = 0.45 (the default task's)."""
    _check_camera(camera, "mountain_car")
    lo, hi, pos = _f(params.min_position), _f(params.max_position), _f(physics.position)
    canvas = Canvas(width, height, (lo, hi), (0.0, 1.2))
    canvas.graph(_hill, lo, hi, 0.01, BLACK)
    flag_x = 0.45
    base = np.array([flag_x, _hill(flag_x)])
    canvas.line(base, base + (0, 0.15), 0.008, BLACK)
    canvas.polygon([base + (0, 0.15), base + (0, 0.11), base + (0.07, 0.13)], (204, 204, 0))
    angle = np.arctan(1.35 * np.cos(3 * pos))  # the slope of the hill under the car
    tangent, normal = np.array([np.cos(angle), np.sin(angle)]), np.array([-np.sin(angle), np.cos(angle)])
    ground = np.array([pos, _hill(pos)])
    car_w, car_h, clearance = 0.12, 0.06, 0.03
    canvas.rectangle(ground + normal * (clearance + car_h / 2), (car_w, car_h), BLACK, angle)
    for side in (-1, 1):
        canvas.disk(ground + tangent * side * car_w / 4 + normal * clearance, car_h / 2.5, (128, 128, 128))
    return canvas.image


def draw_point_mass(physics, params, *, width: int = 320, height: int = 240, camera=-1) -> np.ndarray:
    """The square ``[-bound, bound]^2`` seen from above and the point in it (the goal is not in the physics)."""
    _check_camera(camera, "point_mass")
    bound = _f(params.bound)
    margin = 0.1 * bound
    canvas = Canvas(width, height, (-bound - margin, bound + margin), (-bound - margin, bound + margin), (90, 90, 90))
    canvas.rectangle((0.0, 0.0), (2 * bound, 2 * bound), (235, 235, 235))
    canvas.disk(np.asarray(physics.position, np.float64), 0.05 * bound, (200, 40, 40))
    return canvas.image
