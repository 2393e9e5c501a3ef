"""JAX's persistent compilation cache, switched on at the command line's boundary.

The programs sorjax compiles (the homology fit of one outline, the calibration core
per padded view count, an experiment's trial program) take seconds to tens of seconds
to compile on a CPU: about 14 s for :func:`sorjax.fit_homology`'s, paid once per
process.  The command line (``sorjax calibrate``, ``sorjax experiment``) and the
experiment scripts keep them on disk, so only the first run compiles; a library
import changes no JAX setting (call :func:`enable_compilation_cache` from your own
program to do the same)."""

from __future__ import annotations

import os


def enable_compilation_cache() -> None:
    """Keep compiled XLA programs on disk between runs and worker processes, in
    ``$SORJAX_CACHE`` or else ``$XDG_CACHE_HOME/sorjax/xla`` (``~/.cache/sorjax/xla``),
    so only the first run compiles.  A folder that cannot be made (a read-only home)
    leaves JAX as it was: every run compiles."""
    import jax

    root = os.environ.get("SORJAX_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME", os.path.join(os.path.expanduser("~"), ".cache")), "sorjax", "xla")
    try:
        os.makedirs(root, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", root)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    except Exception:  # a read-only home: compile every time  # pragma: no cover
        pass
