"""How sorjax compiles its programs: XLA options per program, and the on-disk cache.

Time to the first answer is compilation.  A calibration's programs (the homology fit of
one outline, the calibration core per padded view count) are run once or a few times
in a process, so they are compiled for a short compile rather than the fastest run
(:data:`ONE_OFF`: measured on 2 CPU cores, ``experiments/speed.py
--calibrate-program``: the homology fit 13.4 s -> 4.3 s, the bundle's core 25.2 s ->
11.1 s; the core then runs in 93 ms instead of 31 ms).  The options only change how
hard LLVM optimises: the arithmetic is IEEE either way, the results are the same
numbers.  An experiment's trial program, run thousands of times, keeps XLA's defaults
unless the run is short (:func:`options_for_runs`).

Compiled programs are kept on disk (JAX's persistent compilation cache) from sorjax's
first compilation on, in ``$SORJAX_CACHE`` or else ``$XDG_CACHE_HOME/sorjax/xla``
(``~/.cache/sorjax/xla``), so that a second process compiles nothing.  JAX's cache
setting is per process: sorjax leaves it alone when the caller has configured one
(``jax_compilation_cache_dir``), and ``SORJAX_CACHE=off`` (or ``0``, ``none``,
``false``) opts out.  ``SORJAX_FAST_COMPILE=0`` compiles every program with XLA's
defaults.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import io
import os
import pickle
import re
import threading
from typing import Any, Callable

#: XLA CPU options for a program that runs a few times (a calibration): less LLVM
#: optimisation, no expensive LLVM passes, the loop emitters instead of the fusion
#: emitters.  The last two are debug options that a later jaxlib may drop: each set is
#: tried once on a trivial program and left out where XLA refuses it.
ONE_OFF = {"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
           "xla_cpu_use_fusion_emitters": False}

#: Trials of an experiment below which its programs are compiled as :data:`ONE_OFF`
#: (about 14 s less to compile, about 60 ms more a trial: even at about 230 trials).
ONE_OFF_TRIALS = 200

_OPT_OUT = ("off", "0", "none", "false", "no")
_cache_done = False
_LOCK = threading.Lock()
_POOL = None


def _pool():
    """The host thread that prepares programs ahead of their call (one: XLA compiles a
    program on about one core, and the caller's own work takes the other)."""
    global _POOL
    with _LOCK:
        if _POOL is None:
            from concurrent.futures import ThreadPoolExecutor

            _POOL = ThreadPoolExecutor(max_workers=1, thread_name_prefix="sorjax-compile")
    return _POOL


def cache_dir() -> str | None:
    """The folder of sorjax's on-disk compilation cache, or None when opted out."""
    env = os.environ.get("SORJAX_CACHE")
    if env is not None and env.strip().lower() in _OPT_OUT:
        return None
    return env or os.path.join(os.environ.get("XDG_CACHE_HOME", os.path.join(os.path.expanduser("~"), ".cache")),
                               "sorjax", "xla")


def enable_compilation_cache() -> None:
    """Keep compiled XLA programs on disk between runs and worker processes
    (:func:`cache_dir`), so only the first run compiles.  A folder that cannot be made
    (a read-only home) leaves JAX as it was: every run compiles."""
    global _cache_done
    import jax

    _cache_done = True
    root = cache_dir()
    if root is None:
        return
    try:
        os.makedirs(root, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", root)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    except Exception:  # a read-only home: compile every time  # pragma: no cover
        pass


def ensure_cache() -> None:
    """At sorjax's first compilation: the on-disk cache on, unless the caller has
    configured JAX's own (``jax_compilation_cache_dir``) or opted out
    (``SORJAX_CACHE=off``).  Called before each of sorjax's compiled programs runs;
    only the first call does anything."""
    global _cache_done
    if _cache_done:
        return
    import jax

    _cache_done = True
    if jax.config.jax_compilation_cache_dir:
        return
    enable_compilation_cache()


@functools.cache
def _usable(options: tuple) -> dict[str, Any] | None:
    """``options`` (sorted items) as a dict where XLA accepts them, else the subset it
    accepts (tried one by one on a trivial program), None when empty."""
    import jax
    import jax.numpy as jnp

    def works(opts):
        try:
            jax.jit(lambda x: x + 1, compiler_options=opts).lower(jnp.zeros(())).compile()
            return True
        except Exception:
            return False

    opts = dict(options)
    if not works(opts):
        opts = {k: v for k, v in opts.items() if works({k: v})}
    return opts or None


def compiler_options(options: dict[str, Any] | None = ONE_OFF) -> dict[str, Any] | None:
    """The part of ``options`` this jaxlib accepts (None: XLA's defaults; also with
    ``SORJAX_FAST_COMPILE=0``)."""
    if not options or os.environ.get("SORJAX_FAST_COMPILE", "1").strip().lower() in _OPT_OUT:
        return None
    return _usable(tuple(sorted(options.items())))


def options_for_runs(n_runs: int) -> dict[str, Any] | None:
    """Compiler options for a program run ``n_runs`` times: :data:`ONE_OFF` below
    :data:`ONE_OFF_TRIALS`, else XLA's defaults."""
    return compiler_options(ONE_OFF if n_runs < ONE_OFF_TRIALS else None)


def _equinox_missing():
    """equinox's MISSING sentinel (a pytree's aux data holds it; it must unpickle as
    the same object)."""
    from equinox._module._flatten import MISSING

    return MISSING


def _pickle(obj) -> bytes:
    """``pickle.dumps`` with equinox's MISSING sentinel kept a singleton."""
    try:
        missing = _equinox_missing()
    except Exception:  # pragma: no cover - another equinox
        missing = object()

    class _Pickler(pickle.Pickler):
        def reducer_override(self, o):
            return (_equinox_missing, ()) if o is missing else NotImplemented

    buf = io.BytesIO()
    _Pickler(buf, protocol=4).dump(obj)
    return buf.getvalue()


@functools.cache
def _source_hash() -> str:
    """A hash of sorjax's own source files and the versions of what compiles them: a
    stored program is reused only by the code that made it."""
    import importlib.metadata

    import jax

    versions = []
    for dist in ("jax", "jaxlib", "equinox", "optimistix", "lineax", "jaxtyping", "numpy"):
        try:
            versions.append(f"{dist}={importlib.metadata.version(dist)}")
        except importlib.metadata.PackageNotFoundError:  # pragma: no cover
            versions.append(f"{dist}=?")
    h = hashlib.sha256(f"{' '.join(versions)} {jax.default_backend()} {jax.config.jax_enable_x64}".encode())
    root = os.path.dirname(os.path.abspath(__file__))
    for dirpath, dirnames, filenames in sorted(os.walk(root)):
        dirnames.sort()
        for name in sorted(filenames):
            if name.endswith(".py"):
                with open(os.path.join(dirpath, name), "rb") as f:
                    h.update(name.encode() + f.read())
    return h.hexdigest()[:24]


_LAPACK = tuple(f"lapack_{t}{op}_ffi" for t in "sdcz" for op in (
    "geqrf", "geqp3", "orgqr", "ungqr", "ormqr", "unmqr", "getrf", "potrf", "gesdd", "gesvd", "syevd", "heevd",
    "trsm", "gees", "geev", "gehrd", "sytrd", "hetrd", "tridiagonal", "tridiagonal_solve"))


def exports_enabled() -> bool:
    """Whether traced programs are stored (``jax.export``) beside the compilation
    cache: with the cache on, unless ``SORJAX_EXPORT=0``."""
    return cache_dir() is not None and os.environ.get("SORJAX_EXPORT", "1").strip().lower() not in _OPT_OUT


class one_off_jit:
    """``jax.jit(fn, **jit_kwargs)`` compiled with :data:`ONE_OFF`'s options (where
    this jaxlib accepts them), with the on-disk cache switched on before its first
    compilation (:func:`ensure_cache`), and with its traced program stored too.

    Tracing a calibration's programs takes about 9 s on a CPU, every process.  So each
    program is exported (:func:`jax.export.export`, StableHLO, per input structure,
    shapes and static arguments) into ``<cache>/exported/`` with the structure of its
    output, keyed by a hash of sorjax's source and JAX's version: a later process
    deserialises it and compiles it (from the compilation cache) without tracing.
    Anything that goes wrong there falls back to tracing, as ``jax.jit``.  Inside
    another transformation (an outer ``jit``, ``vmap`` or ``grad``) it is the plain
    jitted function.  ``lower`` and ``__wrapped__`` as ``jax.jit``'s."""

    def __init__(self, fn: Callable, static_argnames: tuple[str, ...] = (), **jit_kwargs):
        functools.update_wrapper(self, fn)  # also sets __wrapped__
        self._static = tuple(static_argnames)
        self._kwargs = dict(jit_kwargs, static_argnames=self._static)
        self._jitted = self._plain = None
        self._signature = inspect.signature(fn)
        self._programs: dict[str, tuple[Callable, Any]] = {}
        self._pending: dict[str, Any] = {}  # key -> the Future of a program being prepared (:meth:`prepare`)
        self._cannot_store = False  # an export failed here once: trace as jax.jit from then on

    def jitted(self):
        if self._jitted is None:
            import jax

            ensure_cache()
            self._jitted = jax.jit(self.__wrapped__, compiler_options=compiler_options(), **self._kwargs)
        return self._jitted

    def lower(self, *args, **kwargs):
        return self.jitted().lower(*args, **kwargs)

    def __call__(self, *args, **kwargs):
        import jax

        ensure_cache()
        leaves = jax.tree_util.tree_leaves((args, kwargs))
        if any(isinstance(x, jax.core.Tracer) for x in leaves):
            # inside another transformation: compile options belong to the outermost jit
            if self._plain is None:
                self._plain = jax.jit(self.__wrapped__, **self._kwargs)
            return self._plain(*args, **kwargs)
        if self._cannot_store or not exports_enabled():
            return self.jitted()(*args, **kwargs)
        try:
            run = self._program(args, kwargs)
        except Exception:  # export or deserialisation failed: trace as jax.jit does, and not twice again
            self._cannot_store = True
            return self.jitted()(*args, **kwargs)
        return run()

    def prepare(self, *args, **kwargs) -> None:
        """Make this program for arguments like these (arrays of the same structure,
        shapes and dtypes; their values do not matter) and start compiling it (or
        loading it from the compilation cache) in a host thread, while the caller goes
        on.  The tracing happens here, in the caller's thread (it holds Python's lock
        anyway); XLA compiles outside that lock, so the program compiles beside the
        caller's next work on a second core: :func:`sorjax.calibrate` prepares its core
        before the per-view fits trace, compile and run.  The call with arguments of the
        same structure waits for the compilation.  Does nothing when the program is
        there already or programs are not stored; a failure here is left to that call."""
        import jax

        ensure_cache()
        if self._cannot_store or not exports_enabled():
            return
        try:
            key, flat, in_tree, static = self._key(args, kwargs)
            with _LOCK:
                if key in self._programs or key in self._pending:
                    return
            call, _, out_tree = self._build(key, flat, in_tree, static)
            lowered = call.lower(*[jax.ShapeDtypeStruct(x.shape, x.dtype) for x in flat])
        except Exception:  # left to the call
            return

        def finish():
            self._programs[key] = program = (call, lowered.compile(), out_tree)
            return program

        pool = _pool()
        with _LOCK:
            self._pending[key] = pool.submit(finish)

    def _key(self, args, kwargs):
        """``(key, flat dynamic leaves, their tree, static arguments)`` of a call."""
        import jax
        import numpy as np

        bound = self._signature.bind(*args, **kwargs)
        bound.apply_defaults()
        static = {k: v for k, v in bound.arguments.items() if k in self._static}
        dynamic = {k: v for k, v in bound.arguments.items() if k not in self._static}
        flat, in_tree = jax.tree_util.tree_flatten(dynamic)
        flat = [np.asarray(x) if not isinstance(x, jax.Array) else x for x in flat]
        avals = tuple((tuple(x.shape), str(x.dtype)) for x in flat)
        opts = compiler_options()
        key = hashlib.sha256(_pickle((_source_hash(), self.__wrapped__.__module__, self.__wrapped__.__qualname__,
                                      in_tree, avals, sorted(static.items()),
                                      sorted((opts or {}).items())))).hexdigest()[:32]
        return key, flat, in_tree, static

    def _build(self, key: str, flat, in_tree, static):
        """The program of ``key`` (loaded, or exported and stored), jitted with
        :data:`ONE_OFF`'s options."""
        import jax

        exported, out_tree = self._load(key) or self._export(key, flat, in_tree, static)
        self._programs[key] = program = (jax.jit(exported.call, compiler_options=compiler_options()), None, out_tree)
        return program

    def _program(self, args, kwargs):
        """A thunk running the stored program on these arguments (loading it, or
        exporting and storing it, on first use; waiting for :meth:`prepare`'s)."""
        import jax

        key, flat, in_tree, static = self._key(args, kwargs)
        with _LOCK:
            pending = self._pending.pop(key, None)
        if pending is not None:
            try:
                pending.result()
            except Exception:  # made again below, where its error (if any) surfaces
                self._programs.pop(key, None)
        program = self._programs.get(key) or self._build(key, flat, in_tree, static)
        call, compiled, out_tree = program

        def run():
            if compiled is not None:
                try:
                    return jax.tree_util.tree_unflatten(out_tree, compiled(*flat))
                except TypeError:  # arguments typed otherwise than the prepared ones (weak types)
                    pass
            return jax.tree_util.tree_unflatten(out_tree, call(*flat))

        return run

    @staticmethod
    def _path(key: str) -> str:
        return os.path.join(cache_dir(), "exported", key + ".bin")

    def _load(self, key: str):
        path = self._path(key)
        if not os.path.exists(path):
            return None
        import jax

        try:
            with open(path, "rb") as f:
                blob = pickle.load(f)
            return jax.export.deserialize(bytearray(blob["exported"])), pickle.loads(blob["out_tree"])
        except Exception:  # a truncated or foreign file: export again
            return None

    def _export(self, key: str, flat, in_tree, static):
        import jax

        fn, box = self.__wrapped__, {}

        def flat_fn(*leaves):
            out = fn(**jax.tree_util.tree_unflatten(in_tree, leaves), **static)
            out_leaves, box["tree"] = jax.tree_util.tree_flatten(out)
            return out_leaves

        shapes = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in flat]
        targets = set(_LAPACK)
        for _ in range(3):  # LAPACK's custom calls: stored for this very jaxlib only (the key has its version)
            checks = [jax.export.DisabledSafetyCheck.custom_call(t) for t in sorted(targets)]
            try:
                exported = jax.export.export(jax.jit(flat_fn), disabled_checks=checks)(*shapes)
                break
            except ValueError as e:
                more = set(re.findall(r"custom_call @([A-Za-z0-9_]+)", str(e))) - targets
                if not more:
                    raise
                targets |= more
        else:
            raise RuntimeError("custom calls")
        out_tree = box["tree"]
        path = self._path(key)
        try:
            os.makedirs(os.path.dirname(path), exist_ok=True)
            tmp = f"{path}.{os.getpid()}.tmp"
            with open(tmp, "wb") as f:
                f.write(_pickle({"exported": bytes(exported.serialize()), "out_tree": _pickle(out_tree)}))
            os.replace(tmp, path)
        except OSError:  # a read-only cache: keep it in this process only
            pass
        return exported, out_tree
