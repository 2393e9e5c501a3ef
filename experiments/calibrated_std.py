"""Is the reported uncertainty right?  Per cell of an experiment run, the bundle's
reported standard deviations against its actual errors.

Reads a run's ``results.json`` (``sorjax experiment CONFIG`` writes one per run, with
every trial's estimate, truth and reported std) and prints, for each cell (f, views,
sigma) and each method that reports a std, over the successful trials that are not
gross failures:

* ``std/RMS``: the median reported std of ``fv`` over the RMS error of ``fv`` (1 when
  the std is right; below 1 it is too small);
* ``rms z``: the RMS of ``z = (estimate - truth) / std`` for ``fv`` (1 when right);
* ``>3``: how many of the trials lie beyond 3 of their reported std (``fu, fv, u0,
  v0`` counted separately; about 0.3 % of them when the errors are Gaussian), and the
  worst ``|z|``.

    python experiments/calibrated_std.py runs/table1/<stamp>/results.json
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np


def cells(results: dict):
    """``{(row, method): (errors (n, 4) px, stds (n, 4) px)}`` over the successful,
    non-gross trials with a finite std."""
    out: dict = {}
    for rec in results["records"]:
        truth = rec.get("K_true")
        if truth is None:
            continue
        for m, r in rec["methods"].items():
            std = np.asarray(r.get("std", [math.nan] * 4), float)
            if not r.get("success") or r.get("gross") or not np.all(np.isfinite(std)) or np.any(std <= 0):
                continue
            e = np.asarray(r["estimate"], float) - np.asarray(truth, float)
            out.setdefault((rec["row"], m), ([], []))
            out[(rec["row"], m)][0].append(e)
            out[(rec["row"], m)][1].append(std)
    return {k: (np.array(a), np.array(b)) for k, (a, b) in out.items()}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("results", help="a run's results.json")
    a = p.parse_args(argv)
    results = json.load(open(a.results))
    rows = {s["row"]: s for s in results["summary"]}
    print(f"{'f':>6} {'views':>5} {'sigma':>5} {'method':>12} {'n':>4} {'std/RMS':>8} {'rms z':>6} {'>3':>4} "
          f"{'worst':>6}")
    total = beyond = 0
    for (row, m), (e, s) in sorted(cells(results).items()):
        if len(e) < 5:
            continue
        z = e / s
        ratio = np.median(s[:, 1]) / np.sqrt(np.mean(e[:, 1] ** 2))
        n3 = int(np.sum(np.abs(z) > 3))
        total += z.size
        beyond += n3
        r = rows.get(row, {})
        print(f"{r.get('f', math.nan):6.0f} {r.get('n_views', 0):5d} {r.get('sigma', math.nan):5.2f} {m:>12} "
              f"{len(e):4d} {ratio:8.2f} {np.sqrt(np.mean(z[:, 1] ** 2)):6.2f} {n3:4d} {np.abs(z).max():6.1f}")
    print(f"beyond 3 std: {beyond} of {total} ({100 * beyond / max(total, 1):.2f} %; Gaussian errors: 0.27 %)")


if __name__ == "__main__":
    main()
