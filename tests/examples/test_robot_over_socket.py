"""examples/robot_over_socket.py: a robot behind a socket (a fake one in another process) is a host arena that
agents evaluate and train on."""

import importlib.util
import socket
from pathlib import Path

EXAMPLE = Path(__file__).parents[2] / "examples" / "robot_over_socket.py"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_sac_learns_to_drive_the_socket_robot_home():
    spec = importlib.util.spec_from_file_location("robot_over_socket", EXAMPLE)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    # 4,000 steps (1,000 random, then 3,000 of SAC): -6.8, -6.2 and -6.3 with training keys 0, 1 and 2 (8,000: -3.9)
    out = example.main(["--port", str(_free_port()), "--steps", "100", "--train-steps", "4000"])
    assert all(us > 0 for us in out["latency_us"].values())  # the figures themselves are load-dependent
    assert out["random_return"] < -20  # random forces leave the robot far from home
    assert out["sac_return"] > out["random_return"] / 3
