"""Validation of public options at the boundary: plain Python, before anything is
traced or computed; each failure a ValueError that names the option, says what it
must be and shows what was given."""

from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["boolean", "check_options", "check_sizes", "integer", "number"]


def _is_bool(value) -> bool:
    return isinstance(value, (bool, np.bool_))


def number(value, name: str, *, lo: float | None = None, hi: float | None = None, lo_open: bool = False,
           unit: str = "") -> float:
    """``value`` as a float after checking that it is a real number (not a bool),
    finite and within ``[lo, hi]`` (``(lo, hi]`` when ``lo_open``); ``unit`` is
    named in the message (e.g. "px")."""
    if _is_bool(value) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a number{f' ({unit})' if unit else ''}; got {value!r}.")
    x = float(value)
    bad = not math.isfinite(x) or (lo is not None and (x <= lo if lo_open else x < lo)) or (hi is not None and x > hi)
    if bad:
        rng = []
        if lo is not None:
            rng.append(f"{'>' if lo_open else '>='} {lo:g}")
        if hi is not None:
            rng.append(f"<= {hi:g}")
        unit_s = f" {unit}" if unit else ""
        raise ValueError(f"{name} must be a finite number{' ' + ' and '.join(rng) if rng else ''}{unit_s}; "
                         f"got {value!r}.")
    return x


def integer(value, name: str, *, lo: int | None = None, hi: int | None = None, what: str = "") -> int:
    """``value`` as an int after checking that it is an integer (not a bool, not a
    float) within ``[lo, hi]``; ``what`` says what it counts (e.g. "samples per
    outline")."""
    if _is_bool(value) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer{f' ({what})' if what else ''}; got {value!r}.")
    n = int(value)
    if (lo is not None and n < lo) or (hi is not None and n > hi):
        rng = " and ".join(([f">= {lo}"] if lo is not None else []) + ([f"<= {hi}"] if hi is not None else []))
        raise ValueError(f"{name} must be an integer {rng}{f' ({what})' if what else ''}; got {value!r}.")
    return n


def boolean(value, name: str) -> bool:
    """``value`` checked to be True or False (numpy's bool too)."""
    if not _is_bool(value):
        raise ValueError(f"{name} must be True or False; got {value!r}.")
    return bool(value)


MIN_SAMPLES = 10  # fewer samples cannot constrain a homology's 4 parameters robustly
MIN_POINTS = 64  # a resampled outline coarser than this is a polygon, not a silhouette
MAX_POINTS = 1 << 16  # each outline's distance field is (n_points, ...) arrays: beyond, memory and time explode


def check_sizes(n_samples, n_points) -> tuple[int, int]:
    """``n_samples`` (samples per outline of the homology fit) and ``n_points``
    (points of the resampled outline): integers, ``10 <= n_samples <= n_points``,
    ``64 <= n_points <= 65536``."""
    n_samples = integer(n_samples, "n_samples", lo=MIN_SAMPLES, what="samples per outline")
    n_points = integer(n_points, "n_points", lo=MIN_POINTS, hi=MAX_POINTS, what="points of the resampled outline")
    if n_samples > n_points:
        raise ValueError(f"n_samples ({n_samples}) must not exceed n_points ({n_points}).")
    return n_samples, n_points


def check_options(options):
    """``options`` (:class:`sorjax.Options`; None: the defaults) checked field by field:
    each budget an integer (``max_steps`` and ``bundle_max_steps`` >= 1, the others >= 0;
    ``n_samples`` as :func:`check_sizes` says, checked there), each threshold a real
    number that is not NaN (an infinite threshold switches its test off).  Returns the
    options with every field a Python number, so that two equal options compile the
    same program."""
    import dataclasses

    from .core._options import Options

    if options is None:
        return Options()
    if not isinstance(options, Options):
        raise ValueError(f"options must be a sorjax.Options (the thresholds and budgets; sorjax.Options(name=value, "
                         f"...)), or None for the defaults; got {type(options).__name__}.")
    new = {}
    for f in dataclasses.fields(options):
        value, name = getattr(options, f.name), f"options.{f.name}"
        if isinstance(value, np.ndarray) and value.shape == ():
            value = value.item()
        if f.metadata.get("static", False) or f.name == "measured_leave_out":
            lo = 1 if f.name in ("max_steps", "bundle_max_steps") else 0
            new[f.name] = integer(value, name, lo=lo, what="a step or round budget, or a count")
        else:
            if _is_bool(value) or not isinstance(value, numbers.Real) or math.isnan(float(value)):
                raise ValueError(f"{name} must be a real number (a threshold; inf switches its test off); "
                                 f"got {value!r}.")
            new[f.name] = float(value)
    return dataclasses.replace(options, **new)
