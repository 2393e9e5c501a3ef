"""Helpers shared by the experiment scripts."""

from __future__ import annotations

import warnings
from pathlib import Path


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


def realdata_dir() -> Path:
    """``shared/realdata`` beside the repository, or beside the nearest folder above it
    that has one (a git worktree kept elsewhere finds the main checkout's)."""
    repo = Path(__file__).resolve().parents[1]
    return next((a / "shared" / "realdata" for a in repo.parents if (a / "shared" / "realdata").is_dir()),
                repo.parent / "shared" / "realdata")
