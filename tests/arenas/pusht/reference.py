"""A pymunk reference scene built from the facts of Diffusion Policy's ``pusht_env`` (test-only)."""

from __future__ import annotations

import numpy as np
import pymunk

from jarena.arenas.pusht import geometry

SIM_HZ, CONTROL_HZ = 100, 10
K_P, K_V = 100.0, 20.0


class PymunkPushT:
    """The scene in pymunk: walls (segments at 5..506, radius 2), a kinematic disc (radius 15) driven by the PD
    law, and the T (two boxes on one body, mass 1, its centre of gravity set to the mean of the boxes' centroids).
    Shapes keep pymunk's default friction, 0, as ``pusht_env``'s do."""

    def __init__(self, pusher, pose):
        self.space = pymunk.Space()
        self.space.gravity = (0.0, 0.0)
        self.space.damping = 0.0
        ends = [((5, 506), (5, 5)), ((5, 5), (506, 5)), ((506, 5), (506, 506)), ((5, 506), (506, 506))]
        self.space.add(*[pymunk.Segment(self.space.static_body, a, b, 2) for a, b in ends])
        self.agent = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        self.agent.position = tuple(map(float, pusher))
        self.space.add(self.agent, pymunk.Circle(self.agent, 15))
        boxes = [[tuple(map(float, c)) for c in quad] for quad in geometry.box_corners()]
        bar_moment = pymunk.moment_for_poly(1.0, boxes[0])
        self.block = pymunk.Body(1.0, 2 * bar_moment)
        shapes = [pymunk.Poly(self.block, quad) for quad in boxes]
        self.block.center_of_gravity = (shapes[0].center_of_gravity + shapes[1].center_of_gravity) / 2
        self.block.angle = float(pose[2])  # the angle first: setting it turns the body about its centre of gravity
        self.block.position = (float(pose[0]), float(pose[1]))
        self.space.add(self.block, *shapes)
        self.space.step(1.0 / SIM_HZ)  # as pusht_env's reset: one step with the disc at rest

    def step(self, action):
        dt = 1.0 / SIM_HZ
        target = pymunk.Vec2d(*map(float, action))
        for _ in range(SIM_HZ // CONTROL_HZ):
            acceleration = K_P * (target - self.agent.position) - K_V * self.agent.velocity
            self.agent.velocity += acceleration * dt
            self.space.step(dt)

    @property
    def pose(self) -> np.ndarray:
        return np.array([self.block.position.x, self.block.position.y, self.block.angle])

    @property
    def pusher(self) -> np.ndarray:
        return np.array(self.agent.position)


def rollout(pusher, pose, actions) -> tuple[np.ndarray, np.ndarray]:
    """Block poses (T, 3) and pusher positions (T, 2) after each of ``actions`` (T, 2)."""
    scene = PymunkPushT(pusher, pose)
    poses, pushers = [], []
    for action in actions:
        scene.step(action)
        poses.append(scene.pose)
        pushers.append(scene.pusher)
    return np.array(poses), np.array(pushers)
