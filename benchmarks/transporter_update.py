"""One Transporter training update (the paper's networks, batch 1, 36 yaws, Raven's 320 x 160 heightmap) with the
library's FFT correlation against the same update with the correlation as a direct convolution (Ravens'
``tf.nn.convolution``; here ``lax.conv_general_dilated``), and each correlation alone, forward and backward.

    python benchmarks/transporter_update.py [--repeats 5] [--set KEY=VALUE ...]

Prints one line per measurement (updates or correlations per second, best of ``--repeats``, interleaved) and a
JSON summary with the machine.
"""

from __future__ import annotations

import argparse
import json
from unittest import mock

import jax
import jax.numpy as jnp
import numpy as np
from timing import environment, time_interleaved

from jarena.cli import parse_override
from jarena_agents.transporter import agent as transporter_agent
from jarena_agents.transporter import networks

HEIGHT, WIDTH = 320, 160  # Raven's heightmap
library_correlate = networks.correlate


def direct_correlate(scene, kernels):
    """The cross-correlation as one VALID convolution, as Ravens computes it."""
    return jax.lax.conv_general_dilated(scene[None], jnp.transpose(kernels, (1, 2, 3, 0)), (1, 1), "VALID",
                                        dimension_numbers=("NHWC", "HWIO", "NHWC"))[0]


def demonstrations(count: int = 20) -> dict:
    """``count`` random heightmaps and pick-and-place actions inside the image (the update's input data)."""
    rng = np.random.default_rng(0)
    actions = np.stack([rng.integers(40, HEIGHT - 40, count), rng.integers(40, WIDTH - 40, count),
                        rng.integers(40, HEIGHT - 40, count), rng.integers(40, WIDTH - 40, count),
                        rng.uniform(0, 2 * np.pi, count)], axis=1).astype(np.float32)
    return {"rgb": jnp.asarray(rng.integers(0, 256, (count, HEIGHT, WIDTH, 3), dtype=np.uint8)),
            "height": jnp.asarray(rng.uniform(0, 0.05, (count, HEIGHT, WIDTH)).astype(np.float32)),
            "action": jnp.asarray(actions)}


def update_maker(config: dict, correlate):
    """A maker for :func:`time_interleaved`: one training update with ``correlate`` as the transport's."""
    def make():
        cfg = transporter_agent.make_config(transporter_agent.TransporterConfig, config, agent="transporter")
        model = transporter_agent.build_model(cfg)

        def run(ts):  # the correlation is looked up when the update is traced
            with mock.patch.object(networks, "correlate", correlate):
                return model.update(ts)[0]
        return run, model.start(jax.random.key(0), demonstrations()), 1
    return make


def correlation_maker(correlate, crop: int = 64, rotations: int = 36, features: int = 3):
    """A maker: the correlation alone, forward and backward, at the update's shapes."""
    def make():
        key = jax.random.key(1)
        scene = jax.random.normal(key, (HEIGHT + crop, WIDTH + crop, features))
        kernels = jax.random.normal(jax.random.fold_in(key, 1), (rotations, crop + 1, crop + 1, features))
        grad = jax.grad(lambda s, k: jnp.sum(jnp.sin(correlate(s, k))), argnums=(0, 1))

        def run(carry):
            s, k = carry
            gs, gk = grad(s, k)
            return s + 1e-6 * gs, k + 1e-6 * gk
        return run, (scene, kernels), 1
    return make


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--set", action="append", type=parse_override, default=[], metavar="KEY=VALUE",
                        help="a transporter setting over the default config (value as YAML); repeatable")
    args = parser.parse_args()
    config = dict(args.set)
    results = time_interleaved({
        "correlation, FFT (library)": correlation_maker(library_correlate),
        "correlation, direct convolution": correlation_maker(direct_correlate),
        "update, FFT correlation (library)": update_maker(config, library_correlate),
        "update, direct-convolution correlation": update_maker(config, direct_correlate),
    }, args.repeats)
    names = list(results)
    for fast, slow in ((names[0], names[1]), (names[2], names[3])):
        print(f"{fast} / {slow}: {results[fast]['per_s'] / results[slow]['per_s']:.2f}x")
    print(json.dumps({"results": results, "config": config, "environment": environment()}, indent=2, default=str))


if __name__ == "__main__":
    main()
