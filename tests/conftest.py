import os

import jax

jax.config.update("jax_enable_x64", True)

# Compiled programs are kept on disk between test runs (the same cache as the
# experiment runner's: $SORJAX_CACHE or ~/.cache/sorjax/xla): the suite is mostly
# compilation, and a second run on a machine reuses it.  Results do not depend on it.
from sorjax.experiment._runner import enable_compilation_cache  # noqa: E402

enable_compilation_cache()


import pytest  # noqa: E402


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Drop every compiled program after each test module (the next one reloads what
    it needs from the on-disk cache).  In one process the suite's hundreds of XLA
    executables otherwise accumulate (8 GB, and tens of thousands of memory maps: the
    process aborted inside the compilation cache near the end of the suite)."""
    yield
    jax.clear_caches()
