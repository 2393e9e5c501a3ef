import os

import jax

jax.config.update("jax_enable_x64", True)

# Compiled programs are kept on disk between test runs (the same cache as the
# experiment runner's: $SORJAX_CACHE or ~/.cache/sorjax/xla): the suite is mostly
# compilation, and a second run on a machine reuses it.  Results do not depend on it.
from sorjax.experiment._runner import enable_compilation_cache  # noqa: E402

enable_compilation_cache()
