"""Data-parallel training over local devices and several hosts, with JAX's own runtime.

One `Mesh` with a single 'data' axis spans the chosen devices of every process. The global batch
is sharded on its leading axis (NamedSharding(mesh, P('data'))); params, batch_stats and the
optimizer state are replicated (NamedSharding(mesh, P())). The train step is jitted with those
in and out shardings and XLA's SPMD partitioner (GSPMD) does the rest: a mean over the batch
axis (BatchNorm's statistics, the losses) becomes a mean over the global batch, and the
gradients of replicated parameters are summed across devices. A step on D devices therefore
computes what one device would compute on the same global batch, up to float summation order
(tests/train/test_parallel.py holds every family to that).

Several hosts: `start` calls jax.distributed.initialize before anything else runs JAX, with the
coordinator the command was given (`--coordinator HOST:PORT --num-processes N --process-id I`),
or with JAX's own detection of a cluster launcher (SLURM, Open MPI, ...) for `--coordinator
auto`, or where JAX_COORDINATOR_ADDRESS is set (JAX's own variable; the count and index then come
from the flags or the launcher).
Every process runs the same loop in lock step; each builds only its own rows of the global batch
(`local_batch`: a stream's batch is a pure function of (seed, step), and its `rows` argument builds
a slice of it with the rows' own augmentation, data/batches.py) and hands them to its own devices
(jax.make_array_from_process_local_data). Inputs that are the same for every row (a supernet's
subnet masks: the batch's PER_STEP_INPUTS) are replicated, not split. Only the writer (process 0: `is_writer`) writes run
files. The coordination service has no authentication: it binds only to the address given,
never to every interface (JAX's default), so a run on 127.0.0.1 listens on loopback only.

A one-device, one-process layout leaves the loop exactly as it was (no mesh in the step).
"""

from __future__ import annotations

import dataclasses
import os

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .step import batch_on_device

DATA_AXIS = "data"
AUTO = "auto"  # --coordinator auto: JAX detects the cluster launcher (jax.distributed's ClusterEnv)
CPU_COLLECTIVES = "gloo"  # cross-process collectives on the CPU backend (jax_cpu_collectives_implementation)
FORCE_FLAG = "--xla_force_host_platform_device_count"
# a batch's key naming the inputs that are the same for every row (not split over the mesh)
PER_STEP_INPUTS = "per_step_inputs"


class ParallelError(ValueError):
    """A device count, batch size or coordinator that data-parallel training cannot use."""


@dataclasses.dataclass(frozen=True)
class Launch:
    """What the command asked for. devices: local devices per process (None: all of them)."""
    devices: int | None = None
    coordinator: str | None = None
    num_processes: int | None = None
    process_id: int | None = None


_launch = Launch()  # set once by `start`, at the top of a command


def start(launch: Launch) -> None:
    """First JAX call of a command: CPU host devices for `launch.devices`, then
    jax.distributed.initialize where a coordinator is given (or named by JAX's environment).
    ParallelError (naming the flag) where JAX has already started or the flags do not fit."""
    global _launch
    _check_flags(launch)
    try:
        if launch.devices is not None and FORCE_FLAG not in os.environ.get("XLA_FLAGS", ""):
            # only the CPU client reads it; a GPU or TPU backend keeps its own devices
            jax.config.update("jax_num_cpu_devices", launch.devices)
        if launch.coordinator or os.environ.get("JAX_COORDINATOR_ADDRESS"):
            _initialize_distributed(launch)
    except RuntimeError as err:  # JAX refuses both once a backend has started
        raise ParallelError(f"--devices/--coordinator must take effect before JAX starts: {err}. In your own "
                            f"process call dsfec_jax.train.parallel.start first, or set "
                            f"XLA_FLAGS={FORCE_FLAG}=N before starting Python") from err
    _launch = launch


def use_devices(devices: int | None) -> None:
    """Train the next runs of this process on `devices` local devices (None: all), as `--devices`
    does; a library user's or a test's choice after `start` (JAX's device count is fixed by then)."""
    global _launch
    if devices is not None and devices < 1:
        raise ParallelError(f"--devices {devices}: expected a positive count of local devices")
    _launch = dataclasses.replace(_launch, devices=devices)


def start_or_exit(args, command: str) -> None:
    """`start` with a command's --devices, --coordinator, --num-processes and --process-id
    (argtypes.add_parallel_flags; a command without some of them: None); exit with the message
    where they do not fit."""
    try:
        start(Launch(*(getattr(args, name, None) for name in ("devices", "coordinator", "num_processes", "process_id"))))
    except ParallelError as err:
        raise SystemExit(f"{command}: {err}") from err


def _check_flags(launch: Launch) -> None:
    if launch.devices is not None and launch.devices < 1:
        raise ParallelError(f"--devices {launch.devices}: expected a positive count of local devices")
    cluster = (launch.num_processes, launch.process_id)
    if launch.coordinator is None and any(v is not None for v in cluster):
        raise ParallelError("--num-processes/--process-id need --coordinator HOST:PORT (or --coordinator auto)")
    if launch.coordinator not in (None, AUTO):
        host, _, port = launch.coordinator.rpartition(":")
        if not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise ParallelError(f"--coordinator {launch.coordinator!r}: expected HOST:PORT (e.g. 10.0.0.1:1234) or 'auto'")
        if None in cluster:
            raise ParallelError(f"--coordinator {launch.coordinator}: also give --num-processes N and --process-id I")
        if not 0 <= launch.process_id < launch.num_processes:
            raise ParallelError(f"--process-id {launch.process_id}: expected 0 .. --num-processes - 1 "
                                f"({launch.num_processes - 1})")


def _initialize_distributed(launch: Launch) -> None:
    jax.config.update("jax_cpu_collectives_implementation", CPU_COLLECTIVES)
    address = None if launch.coordinator == AUTO else launch.coordinator
    address = address or os.environ.get("JAX_COORDINATOR_ADDRESS")
    # JAX binds the coordinator to every interface ([::]:PORT) unless told; the service has no
    # authentication, so it listens only where the command said it is
    bind = os.environ.get("JAX_COORDINATOR_BIND_ADDRESS", address)
    jax.distributed.initialize(address, launch.num_processes, launch.process_id, coordinator_bind_address=bind)


def is_writer() -> bool:
    """Whether this process writes the run's files (run.json, metrics, checkpoints, reports, weights)."""
    return jax.process_index() == 0


@dataclasses.dataclass(frozen=True)
class Layout:
    """The mesh a run trains on, with how state and batches are placed on it."""
    mesh: Mesh

    @property
    def devices(self) -> int:
        return self.mesh.devices.size

    @property
    def single(self) -> bool:
        """One device in one process: the loop runs as it always has, with no mesh in the step."""
        return self.devices == 1 and jax.process_count() == 1

    @property
    def replicated(self) -> NamedSharding:
        return NamedSharding(self.mesh, PartitionSpec())

    @property
    def batch_sharding(self) -> NamedSharding:
        return NamedSharding(self.mesh, PartitionSpec(DATA_AXIS))

    def record(self) -> dict:
        """run.json's "parallel" field: the launch, not the setup (a resume may change it)."""
        return {"devices": self.devices, "processes": jax.process_count(), "platform": self.mesh.devices.flat[0].platform,
                "mesh": {"axes": list(self.mesh.axis_names), "shape": list(self.mesh.devices.shape)}}

    def check_batch(self, batch_size: int) -> None:
        if batch_size % self.devices:
            raise ParallelError(f"--batch-size {batch_size} (the global batch) does not divide by the {self.devices} "
                                f"devices of the mesh: give a multiple of {self.devices}, or fewer --devices")

    def step(self, step_fn):
        """`step_fn(state, batch) -> (state, metrics)` (jitted or not) jitted on the mesh: state in
        and out replicated (and donated, as the one-device step donates it), the batch placed by
        batch_on_devices."""
        if self.single:
            return step_fn
        # the batch keeps the placement batch_on_devices gave each leaf: split rows, whole per-step inputs
        return jax.jit(step_fn, in_shardings=(self.replicated, None),
                       out_shardings=(self.replicated, self.replicated), donate_argnums=0)

    def local_batch(self, stream, step: int) -> dict:
        """Batch `step` of `stream` on the mesh, this process having built only its own rows."""
        if self.single:
            return batch_on_device(stream.batch(step))
        return self.batch_on_devices(stream.batch(step, rows=self.local_rows(stream.batch_size)))

    def batch_on_devices(self, batch: dict) -> dict:
        """`batch` (this process's rows of the global batch) on the mesh: each leaf of its
        'inputs' and 'targets' one global array sharded on the batch axis, but for the inputs
        named in its PER_STEP_INPUTS, which every process holds whole and which are replicated;
        the copies finished (train.step.batch_on_device says why)."""
        if self.single:
            return batch_on_device(batch)
        per_step = set(batch.get(PER_STEP_INPUTS, ()))

        def rows(a):
            a = np.asarray(a)
            return jax.make_array_from_process_local_data(self.batch_sharding, a,
                                                          (len(a) * jax.process_count(),) + a.shape[1:])

        def whole(a):
            return jax.make_array_from_process_local_data(self.replicated, np.asarray(a))

        inputs = {k: jax.tree.map(whole if k in per_step else rows, v) for k, v in batch["inputs"].items()}
        placed = {"inputs": inputs, "targets": jax.tree.map(rows, batch["targets"])}
        return {**batch, **jax.block_until_ready(placed)}

    def local_rows(self, batch_size: int) -> slice:
        """The rows of a global batch this process's devices hold (one contiguous block: the
        mesh lists each process's devices together)."""
        index = self.batch_sharding.addressable_devices_indices_map((batch_size,)).values()
        return slice(min(i[0].start or 0 for i in index), max(i[0].stop or batch_size for i in index))

    def replicate(self, state: dict) -> dict:
        """`state` replicated on every device of the mesh; with several processes, process 0's
        values (a process that could not read the run directory resumes from what the writer
        restored)."""
        if self.single:
            return state
        host = jax.device_get(state)
        if jax.process_count() > 1:
            from jax.experimental import multihost_utils

            host = jax.device_get(multihost_utils.broadcast_one_to_all(host))
        return jax.tree.map(lambda a: jax.make_array_from_process_local_data(self.replicated, np.asarray(a)), host)

    def on_host(self, state: dict) -> dict:
        """`state` for a computation outside the mesh (validation, precise BN): host arrays that
        the callee places on its own device."""
        return state if self.single else jax.device_get(state)


def layout(devices: int | None = None) -> Layout:
    """The mesh over `devices` local devices of each process (default: the launch's --devices,
    else all of them). ParallelError naming --devices where a process has fewer."""
    wanted = devices if devices is not None else _launch.devices
    local = jax.local_devices()
    if wanted is not None and wanted > len(local):
        hint = (f"; on the CPU, start the command with --devices {wanted} (or XLA_FLAGS={FORCE_FLAG}={wanted})"
                if local[0].platform == "cpu" else "")
        raise ParallelError(f"--devices {wanted}: this process has {len(local)} {local[0].platform} device(s){hint}")
    count = wanted or len(local)
    chosen = [d for p in range(jax.process_count()) for d in _process_devices(p)[:count]]
    return Layout(Mesh(np.array(chosen), (DATA_AXIS,)))


def _process_devices(process: int) -> list:
    return sorted((d for d in jax.devices() if d.process_index == process), key=lambda d: d.id)
