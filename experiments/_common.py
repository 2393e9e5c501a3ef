"""Helpers shared by the experiment scripts."""

from __future__ import annotations

import warnings


def recorded(fn, *a, **kw):
    """Call ``fn`` with warnings recorded: ``(result or the ValueError raised, [warning texts])``."""
    with warnings.catch_warnings(record=True) as ws:
        warnings.simplefilter("always")
        try:
            res = fn(*a, **kw)
        except ValueError as err:
            res = err
    return res, [str(w.message) for w in ws]
