"""A robot behind a socket as a jarena arena: the pattern for real robots (ROS 1/2, vendor drivers, simulators in
other processes or languages), run here against a fake robot process on this machine.

    python examples/robot_over_socket.py                       # latency table, then evaluate and train on it
    python examples/robot_over_socket.py --latency-ms 20       # a robot whose control loop runs at 50 Hz

How a robot becomes an arena, in three pieces:

1. **The robot's side** (here :func:`serve`, run in a process of its own): whatever drives the hardware. It answers two
   requests, ``reset`` (with a seed, where the robot's randomness allows one) and ``step`` (an action), with the
   observation, reward and episode flags. Here: newline-delimited JSON over TCP, one fake 1-D robot per
   connection (a mass on a rail pushed by a bounded force toward the origin, 100 steps per episode).
2. **A Gymnasium env that talks to it** (:class:`SocketRobot`): ``reset`` and ``step`` send a request and wait
   for the answer. For ROS, the same class publishes the action on a command topic with ``rclpy`` (or
   ``rospy``) and waits on the state topic's next message; the robot's own control rate sets the latency.
3. **The arena**: ``jarena.arenas.host.from_gymnasium(make_env)``. Every agent that acts on observations (random,
   PPO, SAC, BC, Dreamer) then runs on it through ``evaluate``, ``collect`` and ``train_and_evaluate``, inside
   compiled programs: each step of a batch of B robots is one host call (``io_callback``) that steps B
   connections. Arenas of one batch step together; a single physical robot is a batch of one, and
   ``validate_every=0`` keeps validation from asking for a second robot while training holds the first.

The table this prints splits one step's time: the socket round trip alone (the robot's side plus the
network), Gymnasium's wrappers on top, and the host arena's step from a compiled loop (the JAX callback and
jarena's bookkeeping on top of that).
"""

from __future__ import annotations

import argparse
import json
import socket
import socketserver
import subprocess
import sys
import time

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np

import jarena
import jarena_agents
from jarena.arenas.host import from_gymnasium
from jarena.training import train_and_evaluate

HORIZON = 100  # steps per episode of the fake robot
DT = 0.05  # seconds of simulated time per step


# ---------------------------------------------------------------------------------------------- the robot's side
class _Robot(socketserver.StreamRequestHandler):
    """One connection, one fake robot: position x (m) and velocity v (m/s) on a rail, force in [-1, 1] N."""

    def handle(self):
        rng, x, v, t = np.random.default_rng(), 0.0, 0.0, 0
        for line in self.rfile:
            request = json.loads(line)
            if self.server.latency_s:
                time.sleep(self.server.latency_s)  # the robot's control period
            if request["op"] == "reset":
                rng = np.random.default_rng(request.get("seed"))
                x, v, t = float(rng.uniform(-1, 1)), 0.0, 0
                answer = {"obs": [x, v]}
            else:
                force = float(np.clip(request["action"][0], -1, 1))
                v += DT * (force - 0.1 * v)
                x += DT * v
                t += 1
                answer = {"obs": [x, v], "reward": -x * x - 0.01 * force * force, "terminated": False,
                          "truncated": t >= HORIZON}
            self.wfile.write((json.dumps(answer) + "\n").encode())


class _Server(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True


def serve(port: int, latency_s: float) -> None:
    """Runs the fake robot server on ``localhost:port``, forever."""
    with _Server(("127.0.0.1", port), _Robot) as server:
        server.latency_s = latency_s
        server.serve_forever()


def start_robot_process(port: int, latency_ms: float) -> subprocess.Popen:
    """This file run as the fake robot server in a process of its own, once it accepts connections."""
    process = subprocess.Popen([sys.executable, __file__, "--serve", "--port", str(port),
                                "--latency-ms", str(latency_ms)])
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return process
        except OSError:
            if process.poll() is not None:
                raise RuntimeError(f"the fake robot server exited with code {process.returncode}") from None
            time.sleep(0.1)
    process.kill()
    raise RuntimeError(f"the fake robot server did not start on port {port}")


# ------------------------------------------------------------------------------- a Gymnasium env that talks to it
class SocketRobot(gymnasium.Env):
    """The robot as a Gymnasium env: each ``reset`` and ``step`` is one request and its answer."""

    observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (2,), np.float32)
    action_space = gymnasium.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self, address: tuple[str, int]):
        self._socket = socket.create_connection(address)
        self._socket.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # small messages go out at once
        self._stream = self._socket.makefile("rwb")

    def _ask(self, request: dict) -> dict:
        self._stream.write((json.dumps(request) + "\n").encode())
        self._stream.flush()
        return json.loads(self._stream.readline())

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.asarray(self._ask({"op": "reset", "seed": seed})["obs"], np.float32), {}

    def step(self, action):
        answer = self._ask({"op": "step", "action": np.asarray(action, float).tolist()})
        return (np.asarray(answer["obs"], np.float32), float(answer["reward"]), answer["terminated"],
                answer["truncated"], {})

    def close(self):
        self._stream.close()
        self._socket.close()


# ------------------------------------------------------------------------------------------------ measurements
def latency_table(address, steps: int) -> dict[str, float]:
    """Microseconds per step: the socket round trip, the Gymnasium env, and the host arena (B = 1)."""
    robot = SocketRobot(address)
    robot.reset(seed=0)
    t0 = time.perf_counter()
    for _ in range(steps):
        robot._ask({"op": "step", "action": [0.0]})
    socket_us = (time.perf_counter() - t0) / steps * 1e6
    t0 = time.perf_counter()
    for _ in range(steps):
        robot.step(np.zeros(1, np.float32))
    env_us = (time.perf_counter() - t0) / steps * 1e6
    robot.close()

    arena = from_gymnasium(lambda: SocketRobot(address), name="robot-socket")
    run = jax.jit(lambda state: jax.lax.scan(
        lambda s, _: (jarena.batch_step(arena, s, jnp.zeros((1, 1), jnp.float32))[0], None), state, None,
        length=steps)[0])
    state = jax.block_until_ready(run(jarena.batch_reset(arena, jax.random.key(0), 1)[0]))  # compile, warm up
    t0 = time.perf_counter()
    jax.block_until_ready(run(state))
    arena_us = (time.perf_counter() - t0) / steps * 1e6
    return {"socket round trip": socket_us, "Gymnasium env step": env_us, "host arena step (jit)": arena_us}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--port", type=int, default=47321, help="the fake robot server's port on localhost")
    parser.add_argument("--latency-ms", type=float, default=0.0, help="the fake robot's control period")
    parser.add_argument("--steps", type=int, default=2000, help="steps timed for the latency table")
    parser.add_argument("--robots", type=int, default=4, help="robots (connections) trained on in parallel")
    parser.add_argument("--train-steps", type=int, default=8000, help="SAC's environment steps (0: no training)")
    parser.add_argument("--serve", action="store_true", help="only run the fake robot server (used internally)")
    args = parser.parse_args(argv)
    if args.serve:
        return serve(args.port, args.latency_ms / 1e3)

    server = start_robot_process(args.port, args.latency_ms)
    address = ("127.0.0.1", args.port)
    try:
        table = latency_table(address, args.steps)
        print("\nOne step of one robot (microseconds):")
        for name, us in table.items():
            print(f"  {name:24s} {us:9.1f}")
        # the robot ends its episodes itself; jarena's time limit says how long they are, for runners' loops
        arena = from_gymnasium(lambda: SocketRobot(address), name="robot-socket", time_limit=HORIZON,
                               eval_episodes=8, val_episodes=4)
        random = jarena.evaluate(jarena_agents.build_agent("random"), arena).summary()["return_mean"]
        print(f"\nrandom actions: mean return {random:.1f} over 8 eval episodes (0 is best)")
        out = {"latency_us": table, "random_return": random}
        if args.train_steps:
            sac = jarena_agents.build_agent("sac", {"num_arenas": args.robots, "total_steps": args.train_steps,
                                                    "learning_starts": 1000, "hidden": [64, 64]})
            result = train_and_evaluate(sac, arena, jax.random.key(0), validations=2)
            out["sac_return"] = result.evaluation.summary()["return_mean"]
            print(f"SAC after {args.train_steps} steps on {args.robots} robots: mean return {out['sac_return']:.1f}")
        return out
    finally:
        server.terminate()
        server.wait()


if __name__ == "__main__":
    main()
