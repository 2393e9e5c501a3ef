"""sorjax's functional core: the whole calibration as pure functions of fixed-shape
arrays and ``equinox`` pytrees (jit / vmap / grad / shard clean).

The data flow reads like the paper: outline points (V, M, 2) -> :func:`prepare_views`
(normalisation, distance fields, samples, weights) -> per-view harmonic homologies ->
the linear Methods I / IIa / IIb -> the joint bundle -> a result of arrays (K,
covariance, integer codes, per-view diagnostics).  Views are masked, never removed, so
a batch of calibrations stacks; thresholds live in :class:`Options` (static).

:func:`sorjax.calibrate` is the friendly shell over this core: validation, warnings,
messages.

The modules, in the order of the data flow (each imports only those before it;
``tests/test_layout.py`` holds the layers): ``_options``; the geometry ``_camera``,
``_distortion``, ``_field``, ``_symmetry``, ``_solvers``; the per-view fit
``_prepare``, ``_noise``, ``_viewfit``; the linear methods ``_linear``; the bundle
``_bundle``; checks and uncertainty ``_assess``, ``_checks``, ``_result``; the
calibration ``_calibrate``; and ``_shard`` for studies over devices.  The public
names below are loaded on first use (PEP 562), so that a module importing the
geometry does not load the estimator.
"""

import importlib as _importlib

_EXPORTS = {
    "calibrate": "_calibrate", "calibrate_homologies": "_calibrate", "calibrate_methods": "_calibrate",
    "fit_homologies": "_calibrate", "ModelChecks": "_checks", "Options": "_options", "Views": "_prepare",
    "joint_transform": "_prepare", "prepare_views": "_prepare", "RESULTS": "_result", "CoreResult": "_result",
    "TrialSharder": "_shard", "compile_together": "_shard", "host_threads": "_shard", "sharded_vmap": "_shard",
    "ViewFit": "_viewfit", "ViewHomologies": "_viewfit", "fit_view": "_viewfit", "fit_views": "_viewfit",
    "homologies_in_pixels": "_viewfit", "with_noise_floor": "_viewfit",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name):
    if name in _EXPORTS:
        value = getattr(_importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS))
