"""Transporter on a mesh of devices: each device computes the losses of its share of a batch, and the update gives
one device's numbers."""

import os
import subprocess
import sys

WORK = """
import jax, jax.numpy as jnp, numpy as np
from jarena.platform import enable_compilation_cache
enable_compilation_cache(min_compile_secs=0)  # the suite's cache (JARENA_COMPILATION_CACHE, set by conftest.py)
from jarena import distributed
from jarena_agents.transporter.agent import TransporterConfig, build_model, make_config
cfg = make_config(TransporterConfig, {"widths": [8, 16], "head": 8, "crop": 16, "batch_size": 8, "rotations": 4},
                  agent="transporter")
model = build_model(cfg)
rng = np.random.default_rng(0)
height, width, steps = 48, 32, 6
data = {"rgb": jnp.asarray(rng.integers(0, 256, (steps, height, width, 3), dtype=np.uint8)),
        "height": jnp.asarray(rng.uniform(0, 0.05, (steps, height, width)).astype(np.float32)),
        "action": jnp.asarray(np.stack([rng.integers(10, 38, steps), rng.integers(10, 22, steps),
                                        rng.integers(10, 38, steps), rng.integers(10, 22, steps),
                                        rng.uniform(0, 6, steps)], 1).astype(np.float32))}
losses, moments, flops = {}, {}, {}
for devices in (1, 4):
    mesh = distributed.mesh(devices)
    with distributed.tracing_on(mesh):
        state = jax.device_put(model.start(jax.random.key(0), data), distributed.replicated(mesh))
        compiled = jax.jit(model.update).lower(state).compile()
        cost = compiled.cost_analysis()
        flops[devices] = (cost[0] if isinstance(cost, list) else cost)["flops"]
        state, metrics = compiled(state)
    losses[devices] = [float(metrics[k]) for k in ("attention_loss", "transport_loss")]
    # after one update Adam's first moment is 0.1 x the gradient: the gradients of the two runs, compared
    moments[devices] = {jax.tree_util.keystr(path): np.asarray(x) for path, x in
                        jax.tree_util.tree_leaves_with_path(distributed.fetch(state.opt_state))
                        if jnp.issubdtype(x.dtype, jnp.floating) and x.ndim}
np.testing.assert_allclose(losses[4], losses[1], rtol=1e-5)
assert moments[1].keys() == moments[4].keys() and len(moments[1]) > 20
# The attention's last bias (its last block's, added to the output) shifts every pick logit alike, which the softmax
# ignores: its gradient is rounding (1e-9), compared with none. Every other gradient matches.
last = max(int(k.split("['Block_")[1].split("']")[0]) for k in moments[1] if "['attention']" in k and "['Block_" in k)
shift_invariant = [k for k in moments[1] if f"['attention']['params']['Block_{last}']" in k and k.endswith("['bias']")
                   and moments[1][k].shape == (1,)]
assert len(shift_invariant) == 2, shift_invariant  # Adam's mu and nu
for name, value in moments[1].items():
    if name in shift_invariant:
        continue
    np.testing.assert_allclose(moments[4][name], value, rtol=1e-3, atol=1e-4 * float(np.max(np.abs(value))),
                               err_msg=name)
print("PER-DEVICE FLOPS RATIO", flops[4] / flops[1])
"""


def test_four_devices_split_the_batch_and_train_as_one_device():
    """Batches of 8 demonstrations over 4 CPU devices: each device computes about a quarter of the update (the
    losses of its 2 samples), and the update's losses and gradients (Adam's first moments) are one device's."""
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", WORK], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-4000:]
    ratio = float(out.stdout.split("PER-DEVICE FLOPS RATIO")[1])
    assert 0.2 < ratio < 0.35, ratio
