"""Monte-Carlo studies over many devices: a leading *trial* axis sharded over a mesh.

A study is one pure function of one trial's arrays (a calibration, a loss, a field),
``jax.vmap``-ed over trials and ``jax.jit``-ed once; :class:`TrialSharder` spreads the
trial axis over every device JAX sees (a 1-D :class:`jax.sharding.Mesh` with axis
name ``"trials"``), so each device runs its share of the trials and nothing else is
communicated.

Growing past one machine
------------------------
The same program runs on a cluster: start one process per host, call
``jax.distributed.initialize()`` in each (coordinator address, process count and id
from the arguments or the cluster's environment: SLURM, Cloud TPU, ...) *before* any
other JAX call, then build the same :class:`TrialSharder` on every host.
``jax.devices()`` then lists the devices of every host, the mesh spans them all (the
global mesh), and every host runs this same program on the same (global) batch: each
feeds only its own devices' trials (:func:`jax.make_array_from_callback` reads just
the addressable slices) and holds only its devices' results.  Gather results to every
host with :func:`jax.experimental.multihost_utils.process_allgather` (or write each
host's :attr:`jax.Array.addressable_shards` to disk).  Nothing in the study function
changes.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

TRIALS = "trials"


def host_threads() -> int:
    """The CPU cores this process may run on (its affinity mask where the system has
    one): how many parts :class:`TrialSharder` splits a batch into on one CPU device."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


class TrialSharder:
    """``fn`` (one trial's arrays -> a pytree of arrays) vmapped over a leading trial
    axis, jitted, with that axis sharded over a 1-D mesh of ``devices`` (default: every
    device JAX sees, ``jax.devices()``).

    Example::

        run = TrialSharder(lambda pts: sorjax.losses.calibrated_intrinsics(pts, start, 40))
        k = run(points)          # points (n_trials, V, M, 2) -> k (n_trials, 4)

    Every positional argument of :meth:`__call__` is a pytree whose leaves all have the
    trial axis first, with the same length ``n``; arguments shared by every trial
    belong in ``fn``'s closure.  The trial axis is padded to a multiple of the device
    count by repeating the last trial, placed with ``NamedSharding(mesh,
    PartitionSpec("trials"))``, and the padding dropped from the outputs.  When ``n``
    divides evenly the outputs stay sharded over the trials; otherwise dropping the
    padding gathers them onto every device (replicated; results are small).

    On one CPU device (``batch="map"``, the default there) the trials run one after
    another in a compiled loop (``jax.lax.map``), and the batch is split into
    ``threads`` equal parts (default :func:`host_threads`: the cores this process may
    use) run side by side from host threads: XLA's CPU runtime runs one execution
    mostly on one core, so two parts on two cores finish a Table 1 chunk about 1.5x
    sooner (measured on 2 cores).  Each trial's numbers are the same whatever the split
    (the same loop body; tested).

    The vmapped (or mapped), jitted function is built once, here, and held by this
    object, with one executable per input shape and dtype of a part (traced and
    compiled on first use, then reused).  Keep the object for repeated studies;
    building a new one (or calling :func:`sharded_vmap`) traces and compiles again.
    """

    def __init__(self, fn: Callable[..., Any], devices: Sequence[jax.Device] | None = None, batch: str | None = None,
                 threads: int | None = None):
        self.devices = tuple(jax.devices() if devices is None else devices)
        if batch is None:
            batch = "map" if jax.default_backend() == "cpu" and len(self.devices) == 1 else "vmap"
        if batch not in ("vmap", "map"):
            raise ValueError(f"batch must be 'vmap' or 'map'; got {batch!r}")
        if batch == "map" and len(self.devices) > 1:
            raise ValueError("batch='map' runs on one device; use batch='vmap' to shard trials over several "
                             "devices")
        if threads is not None and (isinstance(threads, bool) or not isinstance(threads, (int, np.integer))
                                    or threads < 1):
            raise ValueError(f"threads must be a positive integer (parts run side by side on one CPU device); "
                             f"got {threads!r}")
        self.fn, self.batch = fn, batch
        self.threads = (host_threads() if threads is None else int(threads)) if batch == "map" else 1
        self._executables: dict = {}
        self._pool: ThreadPoolExecutor | None = None
        self.mesh = Mesh(np.asarray(self.devices, dtype=object), (TRIALS,))
        self.sharding = NamedSharding(self.mesh, PartitionSpec(TRIALS))
        if batch == "vmap":
            self.batched = jax.jit(jax.vmap(fn), out_shardings=self.sharding)
        else:  # the trials one after another, in one compiled loop
            self.batched = jax.jit(lambda *xs: jax.lax.map(lambda args: fn(*args), xs))

    @property
    def n_devices(self) -> int:
        return len(self.devices)

    def place(self, *batched_args, multiple: int | None = None):
        """``(n, padded_args)``: the arguments with the trial axis padded to a multiple
        of ``multiple`` (default: the device count) by repeating the last trial, and
        sharded over the mesh."""
        n = self._count(batched_args)
        return n, jax.tree.map(self._put, self._padded(batched_args, n, multiple or self.n_devices))

    def split(self, *batched_args):
        """``(n, parts)``: the arguments padded (repeating the last trial) and cut into
        equal parts along the trial axis, each placed on the mesh: ``threads`` parts on
        one CPU device (fewer for a small batch), else one."""
        n = self._count(batched_args)
        k = min(self.threads, n)
        padded = self._padded(batched_args, n, k * self.n_devices)
        size = -(-n // (k * self.n_devices)) * self.n_devices
        return n, [jax.tree.map(lambda x: self._put(x[i * size:(i + 1) * size]), padded) for i in range(k)]

    @staticmethod
    def shape_key(part):
        """What one executable serves: the shapes and dtypes of a part's leaves (arrays
        or :class:`jax.ShapeDtypeStruct`) and its tree structure."""
        return tuple((np.shape(x), np.result_type(x.dtype)) for x in jax.tree.leaves(part)), jax.tree.structure(part)

    @staticmethod
    def trimmed(out, n: int):
        """``out`` (leading trial axis) without the padding trials beyond the first ``n``."""
        leaves = jax.tree.leaves(out)
        return jax.tree.map(lambda y: y[:n], out) if leaves and leaves[0].shape[0] != n else out

    def executable(self, *part):
        """The compiled program for a part's shapes (traced and compiled on first use;
        ``part`` may hold :class:`jax.ShapeDtypeStruct` leaves)."""
        key = self.shape_key(part)
        if key not in self._executables:
            self._executables[key] = self.batched.lower(*part).compile()
        return self._executables[key]

    def lower(self, *part):
        """The traced program for a part's shapes (``jax.jit(...).lower``), to compile
        with :func:`compile_together` and :meth:`adopt`."""
        return self.batched.lower(*part)

    def adopt(self, part, compiled) -> None:
        """Use ``compiled`` (the compiled :meth:`lower` of ``part``) for ``part``'s shapes."""
        self._executables[self.shape_key(part)] = compiled

    def run_parts(self, exe, parts):
        """``exe`` on every part (side by side from host threads when there are several),
        the outputs concatenated along the trial axis."""
        if len(parts) == 1:
            return exe(*parts[0])
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=self.threads, thread_name_prefix="sorjax-trials")
        outs = list(self._pool.map(lambda p: jax.block_until_ready(exe(*p)), parts))
        return jax.tree.map(lambda *xs: jax.numpy.concatenate(xs, axis=0), *outs)

    def __call__(self, *batched_args):
        """``fn`` of every trial, stacked: a pytree whose leaves have the trial axis
        (length ``n``, padding dropped) first."""
        n, parts = self.split(*batched_args)
        return self.trimmed(self.run_parts(self.executable(*parts[0]), parts), n)

    @staticmethod
    def _count(batched_args) -> int:
        leaves = jax.tree.leaves(batched_args)
        if not leaves:
            raise ValueError("TrialSharder needs at least one array with a leading trial axis")
        sizes = {np.shape(x)[0] if np.ndim(x) else None for x in leaves}
        if len(sizes) != 1 or None in sizes:
            raise ValueError(f"every argument needs the same leading trial axis; got lengths {sorted(map(str, sizes))}")
        (n,) = sizes
        if n == 0:
            raise ValueError("no trials")
        return n

    @staticmethod
    def _padded(batched_args, n: int, multiple: int):
        pad = -n % multiple

        def one(x):
            x = np.asarray(x)
            return np.concatenate([x, np.repeat(x[-1:], pad, axis=0)], axis=0) if pad else x

        return jax.tree.map(one, batched_args)

    def _put(self, x):
        return jax.make_array_from_callback(x.shape, self.sharding, lambda index: x[index])


def compile_together(lowered: Sequence[Any], compiler_options: dict | None = None) -> list[Any]:
    """Compile several traced programs (``jax.stages.Lowered``) side by side from host
    threads: XLA compiles one program mostly on one core, so a study split into
    stages compiles in about the time of its largest stage.  ``compiler_options``:
    XLA's options for each (None: its defaults)."""
    if len(lowered) <= 1:
        return [lo.compile(compiler_options) for lo in lowered]
    with ThreadPoolExecutor(max_workers=min(len(lowered), host_threads())) as pool:
        return list(pool.map(lambda lo: lo.compile(compiler_options), lowered))


def sharded_vmap(fn: Callable[..., Any], *batched_args):
    """One-off ``TrialSharder(fn)(*batched_args)``: ``fn`` over the leading trial axis
    of ``batched_args``, sharded over every device (see :class:`TrialSharder`; it
    compiles on every call, so hold a :class:`TrialSharder` for repeated studies)."""
    return TrialSharder(fn)(*batched_args)
