import os

# The suite is mostly XLA compilation of programs that then run for milliseconds, so
# the tests ask XLA's CPU backend to compile faster: less LLVM optimisation and no
# expensive LLVM passes, and the older loop emitters instead of the fusion emitters
# (calibrate's core program, 4 views: 19.0 s to compile at optimisation level 0, 10.8 s
# with the other two as well; it then runs in 320 ms instead of 290 ms.  Measured by
# ``XLA_FLAGS=... python experiments/speed.py --calibrate-program``).  None of them
# allows fast-math: the arithmetic is IEEE as in a default build.  A flag the caller
# set wins.  XLA aborts on a flag it does not know, and the last two are debug options
# a later jaxlib may drop: they are tried once in a subprocess first (about 1.5 s; the
# worker processes inherit the result) and left out if they fail.
TEST_XLA_FLAGS = {"xla_backend_optimization_level": "0"}
FAST_COMPILE_FLAGS = {"xla_llvm_disable_expensive_passes": "true", "xla_cpu_use_fusion_emitters": "false"}


def _flags_work(flags: str) -> bool:
    import subprocess
    import sys

    env = dict(os.environ, XLA_FLAGS=flags)
    try:
        return subprocess.run([sys.executable, "-c", "import jax; jax.devices()"], env=env, capture_output=True,
                              timeout=120).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


def _test_xla_flags(flags: str) -> str:
    add = lambda f, d: " ".join([f] + [f"--{k}={v}" for k, v in d.items() if k not in f]).strip()  # noqa: E731
    flags = add(flags, TEST_XLA_FLAGS)
    fast = add(flags, FAST_COMPILE_FLAGS)
    return fast if fast == flags or _flags_work(fast) else flags


if "PYTEST_XDIST_WORKER" not in os.environ:  # a worker has its controller's flags
    os.environ["XLA_FLAGS"] = _test_xla_flags(os.environ.get("XLA_FLAGS", ""))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

# Compiled programs are kept on disk between test runs (the same cache as the
# experiment runner's: $SORJAX_CACHE or ~/.cache/sorjax/xla): the suite is mostly
# compilation, and a second run on a machine reuses it.  Results do not depend on it.
from sorjax.experiment._runner import enable_compilation_cache  # noqa: E402

enable_compilation_cache()


import pytest  # noqa: E402

# The suite runs in worker processes (pytest-xdist, ``-n auto --dist loadfile`` in
# pyproject.toml: one test module per worker at a time, so a module's fixtures are built
# once).  One process keeps about 1.3 of the cores busy (XLA compiles one program at a
# time); two on the 2-core machine took the cold suite from 1100 s to 763 s.  Each
# worker holds up to a few GiB of compiled programs, so there are no more workers than
# cores nor than WORKER_BYTES fit in the machine's memory.  ``-n 0`` runs in one
# process.
WORKER_BYTES = 6 * 2**30


def _machine_bytes():
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError):
        return None


def pytest_xdist_auto_num_workers(config):
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    memory = _machine_bytes()
    by_memory = max(1, memory // WORKER_BYTES) if memory else 1
    return max(1, min(cores, by_memory))


def _workers():
    return max(1, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))


# When to drop the compiled programs held in memory (see _release_compiled_programs):
# 10 GiB, or 60 % of the machine's memory shared out among the workers where less.
MAX_RSS_BYTES = min(10 * 2**30, int(0.6 * (_machine_bytes() or 2**36) / _workers()))
MAX_MEMORY_MAPS = 30_000  # the kernel's default limit is 65530


def _process_load():
    """``(resident bytes, memory maps)`` of this process, or None where /proc is not
    readable (then the programs are dropped after every module, as before)."""
    try:
        with open("/proc/self/statm") as f:
            rss = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
        with open("/proc/self/maps") as f:
            maps = sum(1 for _ in f)
    except (OSError, ValueError):
        return None
    return rss, maps


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs(request):
    """Drop every compiled program after a test module once the process holds too many
    (the next module reloads what it needs from the on-disk cache).  In one process the
    suite's hundreds of XLA executables otherwise accumulate (8 GB, and tens of
    thousands of memory maps: the process aborted inside the compilation cache near
    the end of the suite).  Not after every module: dropping them also drops the traced
    programs, and tracing the calibration again costs each module tens of seconds even
    when its executable comes from the disk cache."""
    yield
    load = _process_load()
    if os.environ.get("SORJAX_TEST_LOAD_LOG"):  # where the thresholds come from
        with open(os.environ["SORJAX_TEST_LOAD_LOG"], "a") as f:
            f.write(f"{request.module.__name__} {load}\n")
    if load is None or load[0] > MAX_RSS_BYTES or load[1] > MAX_MEMORY_MAPS:
        jax.clear_caches()
