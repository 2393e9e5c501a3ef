"""sorjax's functional core: the whole calibration as pure functions of fixed-shape
arrays and ``equinox`` pytrees (jit / vmap / grad / shard clean).

The data flow reads like the paper: outline points (V, M, 2) -> :func:`prepare_views`
(normalisation, distance fields, samples, weights) -> per-view harmonic homologies ->
the linear Methods I / IIa / IIb -> the joint bundle -> a result of arrays (K,
covariance, integer codes, per-view diagnostics).  Views are masked, never removed, so
a batch of calibrations stacks; thresholds live in :class:`Options` (static).

:func:`sorjax.calibrate` is the friendly shell over this core: validation, warnings,
messages.
"""

from ._calibrate import calibrate as calibrate, calibrate_homologies as calibrate_homologies
from ._calibrate import calibrate_methods as calibrate_methods, fit_homologies as fit_homologies
from ._checks import ModelChecks as ModelChecks
from ._options import Options as Options
from ._prepare import Views as Views, joint_transform as joint_transform, prepare_views as prepare_views
from ._result import RESULTS as RESULTS, CoreResult as CoreResult
from ._shard import TrialSharder as TrialSharder, compile_together as compile_together
from ._shard import host_threads as host_threads, sharded_vmap as sharded_vmap
from ._viewfit import ViewFit as ViewFit, ViewHomologies as ViewHomologies, fit_view as fit_view
from ._viewfit import fit_views as fit_views, homologies_in_pixels as homologies_in_pixels
from ._viewfit import with_noise_floor as with_noise_floor
