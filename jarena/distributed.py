"""Many devices and many processes: the device mesh training and evaluation run on, through ``jax.sharding``.

jarena spreads work with the engine JAX already has, and nothing home-made: a one-axis :class:`Mesh`
(``"data"``) over the devices a run uses, the arena batch sharded along it, everything else (parameters,
optimiser state, counters) replicated, and XLA's SPMD partitioner inserting the collectives (gradient
all-reduces, the gathers a shuffled minibatch needs). A computation under such a mesh computes the same
numbers as on one device (up to the order of float reductions), so one code path serves 1 device, all the
GPUs of a host and, after :func:`initialize`, all devices of all processes of a cluster.

Multi-process runs: call :func:`initialize` (``jax.distributed.initialize``) in every process before any
other JAX call; each process then runs the same program on its own devices, only the main process
(:func:`is_main_process`) writes logs, and checkpoints are written collectively by all.

The boundary between the collective part of a run and what one process does alone is :func:`fetch`: every
process enters the same compiled programs and the same fetches, in the same order, and whatever only process 0
does afterwards (writing files, rendering videos, printing) works on the host copies ``fetch`` returns, never
on arrays that span processes (a computation on those would be a collective the others never enter). Each fetch
of such arrays is a collective point the run's watchdog (``jarena.watchdog``) follows, so that a process that
dies, hangs or fetches something else makes the others fail within a bounded time instead of waiting forever.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import os
from typing import Any

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jarena import watchdog

try:  # the partitioner switch as a scoped context (see _gspmd_partitioner); absent: JAX's default is kept
    from jax._src import config as jax_config
except ImportError:  # pragma: no cover - a JAX without it
    jax_config = None

PyTree = Any

#: The mesh axis the arena batch is sharded along.
AXIS = "data"

#: Environment variables a launcher sets for :func:`initialize` (on SLURM: from $SLURM_NTASKS and $SLURM_PROCID).
ENVIRONMENT = {"coordinator": "JARENA_COORDINATOR", "num_processes": "JARENA_NUM_PROCESSES",
               "process_id": "JARENA_PROCESS_ID"}


@dataclasses.dataclass(frozen=True)
class Launch:
    """Where this process stands in a multi-process run.

    Attributes:
      coordinator: ``HOST:PORT`` of process 0's coordination service.
      num_processes: processes in the run.
      process_id: this process, ``0 .. num_processes - 1``.
      local_devices: on a CPU-only machine, split the host into this many devices (tests and rehearsals of
        a cluster launch); ``None`` leaves the devices as JAX finds them.
    """

    coordinator: str
    num_processes: int
    process_id: int
    local_devices: int | None = None

    def __post_init__(self):
        host, _, port = self.coordinator.rpartition(":")
        if not host or not port.isdigit():
            raise ValueError(f"coordinator must be HOST:PORT (e.g. 10.0.0.1:1234), got {self.coordinator!r}")
        if not isinstance(self.num_processes, int) or self.num_processes < 1:
            raise ValueError(f"num_processes must be a positive integer, got {self.num_processes!r}")
        if not isinstance(self.process_id, int) or not 0 <= self.process_id < self.num_processes:
            raise ValueError(f"process_id must be in 0 .. {self.num_processes - 1}, got {self.process_id!r}")


def launch_from_environment() -> Launch | None:
    """A :class:`Launch` from ``JARENA_COORDINATOR``, ``JARENA_NUM_PROCESSES`` and ``JARENA_PROCESS_ID``, or
    ``None`` when none is set (a single-process run)."""
    values = {name: os.environ.get(var) for name, var in ENVIRONMENT.items()}
    if not any(values.values()):
        return None
    missing = [ENVIRONMENT[n] for n, v in values.items() if not v]
    if missing:
        raise ValueError(f"a multi-process launch needs all of {', '.join(ENVIRONMENT.values())}; missing "
                         f"{', '.join(missing)}")
    try:
        return Launch(values["coordinator"], int(values["num_processes"]), int(values["process_id"]))
    except ValueError as e:
        raise ValueError(f"bad multi-process launch variables {values}: {e}") from None


_initialized: Launch | None = None


def initialize(launch: Launch | None = None, limits: watchdog.Limits | None = None) -> Launch | None:
    """Joins a multi-process run (``jax.distributed.initialize``); must come before any other JAX call.

    Args:
      launch: where this process stands; default :func:`launch_from_environment`. ``None`` there too: a
        single-process run, nothing to do (returns ``None``).
      limits: how long a process waits on the others before it fails (:class:`jarena.watchdog.Limits`;
        default from ``JARENA_HEARTBEAT_TIMEOUT`` and ``JARENA_WAIT_TIMEOUT``, else 60 s and 900 s).

    On CPU devices the processes exchange data through gloo, JAX's CPU collectives. Each process starts its
    watchdog (``jarena.watchdog``): a process that dies or hangs makes the others fail within those limits,
    saying which one went missing, and at exit every process waits for the others to finish. JAX's preemption
    service stays off: jarena takes no preemption sync points, and with the service on SIGTERM is caught and
    ignored (the process would run on); off, SIGTERM ends the process (and the command line's handler,
    ``jarena.termination``, first lets it close its logs). Calling it again with the same launch does nothing;
    with another one it raises.
    """
    global _initialized
    launch = launch or launch_from_environment()
    if launch is None or launch == _initialized:
        return launch
    if _initialized is not None:
        raise RuntimeError(f"jax.distributed is already initialised for {_initialized}; cannot join {launch}")
    if launch.local_devices is not None:
        _set_cpu_device_count(launch.local_devices)
    limits = limits or watchdog.Limits.from_environment()
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.config.update("jax_enable_preemption_service", False)
    # JAX's own heartbeat is the backstop: it ends the processes (with its own message) only after the
    # watchdog's shorter limit has reported the missing process in jarena's words
    jax.distributed.initialize(coordinator_address=launch.coordinator, num_processes=launch.num_processes,
                               process_id=launch.process_id,
                               heartbeat_timeout_seconds=int(2 * limits.heartbeat + 10))
    _initialized = launch
    watchdog.start(launch, limits)
    return launch


def _set_cpu_device_count(count: int) -> None:
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if "xla_force_host_platform_device_count" not in f]
    os.environ["XLA_FLAGS"] = " ".join(flags + [f"--xla_force_host_platform_device_count={int(count)}"])


def is_main_process() -> bool:
    """Whether this is process 0, the one that writes logs, results and videos."""
    return jax.process_index() == 0


def mesh(devices: int | str | None = None) -> Mesh:
    """A one-axis (``"data"``) mesh over the devices a run uses.

    Args:
      devices: ``"all"`` (every device of every process), a count ``N`` (the first ``N // P`` local devices
        of each of the ``P`` processes), or ``None``: all devices in a multi-process run, else one.

    Raises:
      ValueError: a count that is not a positive multiple of the process count, or more than there are.
    """
    available = jax.devices()
    processes = jax.process_count()
    if devices is None:
        devices = "all" if processes > 1 else 1
    if devices == "all":
        return Mesh(np.asarray(available), (AXIS,))
    if isinstance(devices, str):
        if not devices.isdigit():
            raise ValueError(f"devices must be 'all' or a positive integer, got {devices!r}")
        devices = int(devices)
    if not isinstance(devices, int | np.integer) or devices < 1 or devices > len(available) or devices % processes:
        raise ValueError(f"devices={devices!r}: choose 'all' or a count from 1 to {len(available)} (the "
                         f"{jax.default_backend()} devices here) that is a multiple of the {processes} process(es)")
    per_process = int(devices) // processes
    chosen = [d for p in range(processes) for d in [d for d in available if d.process_index == p][:per_process]]
    return Mesh(np.asarray(chosen), (AXIS,))


def _gspmd_partitioner():
    """A context that lowers programs for XLA's GSPMD partitioner instead of Shardy (JAX's default), or a no-op
    where this JAX has no such switch.

    XLA's CUDA plugin (jax 0.11.2, H100s) segfaults while compiling MJX's solver inside ``jax.shard_map`` for
    two GPUs when the program comes through Shardy, and compiles it through GSPMD (``benchmarks/RESULTS.md``,
    "Scaling over devices"). The partitioner changes how the program is split, never what it computes; the
    switch is scoped to jarena's sharded calls, so the caller's own programs keep JAX's default.
    """
    switch = getattr(jax_config, "use_shardy_partitioner", None)
    return switch(False) if callable(switch) else contextlib.nullcontext()


@contextlib.contextmanager
def tracing_on(mesh: Mesh):
    """A context in which programs are traced, lowered and compiled with ``mesh`` as JAX's current mesh
    (``jax.set_mesh``), so that batched arena code can keep per-arena decisions on each device (see
    ``jarena.core.batching``), through XLA's GSPMD partitioner (:func:`_gspmd_partitioner` says why); a no-op
    for a mesh of one device."""
    if mesh.devices.size < 2:
        yield
        return
    with jax.set_mesh(mesh), _gspmd_partitioner():
        yield


def replicated(mesh: Mesh) -> NamedSharding:
    """A sharding that keeps a whole copy on every device of ``mesh``."""
    return NamedSharding(mesh, PartitionSpec())


PARAMETERS = "params"
"""The dict key under which network parameters live (Flax's collection): :func:`batch_shardings` never splits them."""


def batch_shardings(tree: PyTree, mesh: Mesh, batch_size: int | None) -> PyTree:
    """Shardings for ``tree`` (arrays or ``jax.ShapeDtypeStruct``s): leaves whose leading axis is the arena
    batch (``batch_size``) are split along ``"data"``, all others replicated, and so are network parameters
    whatever their shape: every leaf under a ``"params"`` key (Flax's parameter collection, and what mirrors it:
    optimiser moments, target networks, EMA weights).

    Which leaves are split changes only speed, never results (the partitioner keeps the program's
    meaning); this rule splits what grows with the arena count. Without the parameter exception, a layer as wide
    as the arena count (256 arenas, 256-unit layers) was split over the devices and gathered whole again in
    every gradient step: 30 all-gathers per step in a PPO update on 4 devices.

    Raises:
      ValueError: ``batch_size`` not divisible by the mesh's devices.
    """
    count = mesh.size  # a Mesh, or an AbstractMesh (shardings planned without devices)
    if batch_size is not None and batch_size % count:
        raise ValueError(f"{batch_size} arenas cannot be split evenly over {count} devices; choose num_arenas "
                         f"divisible by {count} or other devices")
    split, whole = NamedSharding(mesh, PartitionSpec(AXIS)), replicated(mesh)

    def rule(path, x):
        shape = getattr(x, "shape", ())
        if batch_size is None or count < 2 or len(shape) < 1 or shape[0] != batch_size:
            return whole
        network = any(isinstance(k, jax.tree_util.DictKey) and k.key == PARAMETERS for k in path)
        return whole if network else split

    return jax.tree_util.tree_map_with_path(rule, tree)


def traced_mesh():
    """The mesh the program is being traced under (:func:`tracing_on`, ``jax.set_mesh``) if its ``"data"`` axis
    splits the batch over several devices, else ``None``."""
    mesh = jax.sharding.get_abstract_mesh()
    if mesh.empty or AXIS not in mesh.axis_names or mesh.shape[AXIS] < 2:
        return None
    return mesh


def split_batch(tree: PyTree, axis: int = 0) -> PyTree:
    """``tree`` with each array's axis ``axis`` (the leading one by default) split along ``"data"`` of the mesh
    the program is traced under (:func:`tracing_on`); unchanged without such a mesh, and for arrays the axis does
    not divide evenly.

    For per-example work a trainer draws itself rather than reading from the arena batch, such as a minibatch
    sampled from a replicated dataset (``bc``): marked so, each device computes the loss of its share and XLA
    sums the gradients across devices, where unmarked every device would compute the whole minibatch. Which
    arrays are split changes only speed, never results (up to the order of float sums).
    """
    mesh = traced_mesh()
    if mesh is None:
        return tree
    count = mesh.shape[AXIS]

    def split(x):
        if getattr(x, "ndim", 0) > axis and x.shape[axis] % count == 0:
            return jax.lax.with_sharding_constraint(x, PartitionSpec(*([None] * axis), AXIS))
        return x

    return jax.tree_util.tree_map(split, tree)


def replicate(tree: PyTree) -> PyTree:
    """``tree`` with every array kept whole on each device of the mesh the program is traced under
    (:func:`tracing_on`); unchanged without such a mesh.

    For what every device needs whole inside a program, where XLA's partitioner would otherwise choose a layout
    itself: parameters inside a training step (left free, it may split a network's layers over the devices and
    all-reduce activations in every matrix product), or a dataset every device draws shuffled minibatches from
    (gathered once instead of at each shuffle). Like :func:`split_batch`, this changes only speed.
    """
    if traced_mesh() is None:
        return tree
    return jax.tree_util.tree_map(lambda x: jax.lax.with_sharding_constraint(x, PartitionSpec())
                                  if isinstance(x, jax.Array) else x, tree)


def fetch(tree: PyTree, name: str = "fetch") -> PyTree:
    """Host (numpy) copies of ``tree``'s arrays (PRNG keys: keys on the default device); a sharded array spanning
    other processes is gathered first (a collective: every process calls it alike).

    Where ``tree`` holds arrays that span processes, this is a collective point of the run's watchdog
    (``jarena.watchdog``): ``name`` (e.g. ``"validation 3"``) and the shapes fetched are what it reports when
    the processes part ways here.
    """
    spanning = [x for x in jax.tree_util.tree_leaves(tree) if isinstance(x, jax.Array) and not x.is_fully_addressable]
    if spanning:
        watchdog.enter(name, _fingerprint(tree))

    def get(x):
        if isinstance(x, jax.Array) and jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
            return jax.random.wrap_key_data(get(jax.random.key_data(x)), impl=jax.random.key_impl(x))
        if isinstance(x, jax.Array) and not x.is_fully_addressable and not x.is_fully_replicated:
            from jax.experimental import multihost_utils

            return np.asarray(multihost_utils.process_allgather(x, tiled=True))
        return jax.device_get(x)

    for x in jax.tree_util.tree_leaves(tree):  # every copy under way before the first is waited for
        if isinstance(x, jax.Array) and x.is_fully_addressable and not jax.dtypes.issubdtype(x.dtype,
                                                                                          jax.dtypes.prng_key):
            x.copy_to_host_async()
    return jax.tree_util.tree_map(get, tree)


def _fingerprint(tree: PyTree) -> str:
    """A short summary of what ``tree`` holds (leaf count, bytes, and a hash of its structure, shapes and dtypes):
    two processes fetching at the same point must agree on it."""
    leaves, structure = jax.tree_util.tree_flatten(tree)
    shapes = [(tuple(np.shape(x)), str(getattr(x, "dtype", type(x).__name__))) for x in leaves]
    size = sum(int(getattr(x, "nbytes", 0) or 0) for x in leaves)
    digest = hashlib.sha1(repr((str(structure), shapes)).encode()).hexdigest()[:10]
    return f"{len(leaves)} arrays, {size} bytes, #{digest}"


def collective_point(name: str) -> None:
    """Marks a point every process of a multi-process run reaches in the same order (a checkpoint save, say), for
    the watchdog (``jarena.watchdog``); nothing in a single-process run."""
    watchdog.enter(name)
