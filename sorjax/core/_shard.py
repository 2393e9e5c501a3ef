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

from collections.abc import Callable, Sequence
from typing import Any

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

TRIALS = "trials"


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

    The vmapped, jitted function is built once, here, and held by this object: it is
    compiled once per input shape and dtype (``jax.jit``'s own cache, which lives as
    long as this object's callable).  Keep the object for repeated studies; building a
    new one (or calling :func:`sharded_vmap`) traces and compiles again.
    """

    def __init__(self, fn: Callable[..., Any], devices: Sequence[jax.Device] | None = None, batch: str | None = None):
        self.devices = tuple(jax.devices() if devices is None else devices)
        if batch is None:
            batch = "map" if jax.default_backend() == "cpu" and len(self.devices) == 1 else "vmap"
        if batch not in ("vmap", "map"):
            raise ValueError(f"batch must be 'vmap' or 'map'; got {batch!r}")
        if batch == "map" and len(self.devices) > 1:
            raise ValueError("batch='map' runs on one device (optimistix's solvers do not run inside "
                             "jax.shard_map); use batch='vmap' to shard trials over several devices")
        self.fn, self.batch = fn, batch
        self.mesh = Mesh(np.asarray(self.devices, dtype=object), (TRIALS,))
        self.sharding = NamedSharding(self.mesh, PartitionSpec(TRIALS))
        if batch == "vmap":
            self.batched = jax.jit(jax.vmap(fn), out_shardings=self.sharding)
        else:  # the trials one after another, in one compiled loop
            self.batched = jax.jit(lambda *xs: jax.lax.map(lambda args: fn(*args), xs))

    @property
    def n_devices(self) -> int:
        return len(self.devices)

    def place(self, *batched_args):
        """``(n, padded_args)``: the arguments with the trial axis padded to a multiple
        of the device count (repeating the last trial) and sharded over the mesh."""
        leaves = jax.tree.leaves(batched_args)
        if not leaves:
            raise ValueError("TrialSharder needs at least one array with a leading trial axis")
        sizes = {np.shape(x)[0] if np.ndim(x) else None for x in leaves}
        if len(sizes) != 1 or None in sizes:
            raise ValueError(f"every argument needs the same leading trial axis; got lengths {sorted(map(str, sizes))}")
        (n,) = sizes
        if n == 0:
            raise ValueError("no trials")
        pad = -n % self.n_devices

        def put(x):
            x = np.asarray(x)
            if pad:
                x = np.concatenate([x, np.repeat(x[-1:], pad, axis=0)], axis=0)
            return jax.make_array_from_callback(x.shape, self.sharding, lambda index: x[index])

        return n, jax.tree.map(put, batched_args)

    def __call__(self, *batched_args):
        """``fn`` of every trial, stacked: a pytree whose leaves have the trial axis
        (length ``n``, padding dropped) first."""
        n, args = self.place(*batched_args)
        out = self.batched(*args)
        if -n % self.n_devices:
            out = jax.tree.map(lambda y: y[:n], out)
        return out


def sharded_vmap(fn: Callable[..., Any], *batched_args):
    """One-off ``TrialSharder(fn)(*batched_args)``: ``fn`` over the leading trial axis
    of ``batched_args``, sharded over every device (see :class:`TrialSharder`; it
    compiles on every call, so hold a :class:`TrialSharder` for repeated studies)."""
    return TrialSharder(fn)(*batched_args)
