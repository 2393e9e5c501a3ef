"""Helpers shared by the experiment scripts."""

from __future__ import annotations

import warnings


def recorded(fn, *a, errors=(ValueError,), **kw):
    """Call ``fn`` with warnings recorded: ``(result or the exception raised of
    ``errors``, [warning texts])``."""
    with warnings.catch_warnings(record=True) as ws:
        warnings.simplefilter("always")
        try:
            res = fn(*a, **kw)
        except errors as err:
            res = err
    return res, [str(w.message) for w in ws]
