"""Summaries, the paper-style table, CSV and figures of an experiment run."""

from __future__ import annotations

import csv
import io
import math

import numpy as np

from .._camera_io import clip_line as _clip_line
from ._config import SWEEPS, Config

NAMES = ("fu", "fv", "u0", "v0")


def summarise(cfg: Config, records: list[dict]) -> list[dict]:
    """Per row and method: RMS of the errors (% of f) over the trials that are not
    gross failures, the counts of failures and gross failures, the median absolute
    focal error, and the mean time per calibration (s)."""
    out = []
    for r, row in enumerate(cfg.rows()):
        recs = [x for x in records if x["row"] == r]
        for m in cfg.methods:
            res = [x["methods"].get(m) for x in recs]
            good = np.array([x["error"] for x in res if x is not None and not x["gross"]]).reshape(-1, 4)
            n_fail = sum(1 for x in res if x is None or not x["success"])
            n_gross = sum(1 for x in res if x is None or x["gross"])
            rms = np.sqrt(np.mean(good**2, axis=0)) if len(good) else np.full(4, np.nan)
            foc = np.array([max(abs(x["error"][0]), abs(x["error"][1])) for x in res if x is not None and x["success"]])
            times = [x["time"] for x in res if x is not None]
            out.append(dict(
                row=r, **row, method=m, trials=len(recs), rms=rms.tolist(),
                focal_rms=float(np.sqrt(np.mean(good[:, :2] ** 2))) if len(good) else math.nan,
                median_focal=float(np.median(foc)) if len(foc) else math.nan,
                failures=n_fail, gross=n_gross, time=float(np.mean(times)) if times else math.nan,
            ))
    return out


def _row_label(row: dict, axes) -> list[str]:
    out = []
    for k in axes:
        v = row[k]
        out.append("random" if v is None else (f"{v:g}" if isinstance(v, float) else str(v)))
    return out


def _axes(cfg: Config) -> list[str]:
    """Columns that label a row: f and sigma always (the paper's layout), plus the
    other swept axes."""
    sw = cfg.swept()
    return [k for k in SWEEPS if k in sw or k in ("f", "sigma")]


def table_markdown(cfg: Config, summary: list[dict], bounds: dict | None = None) -> str:
    """The paper's layout: a row per (f, sigma, ...); per method ``fu / fv / u0 / v0``
    RMS in % of f and the number of gross failures in brackets."""
    axes = _axes(cfg)
    heads = {"f": "f (px)", "sigma": "sigma (px)", "n_views": "views", "shape": "shape"}
    cols = [heads[a] for a in axes] + [f"{m}: fu / fv / u0 / v0 (gross)" for m in cfg.methods]
    bcols = sorted(bounds or {}, key=lambda k: k != "bound")
    cols += [f"{b}: fu / fv / u0 / v0" for b in bcols]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r, row in enumerate(cfg.rows()):
        cells = _row_label(row, axes)
        for m in cfg.methods:
            s = next(x for x in summary if x["row"] == r and x["method"] == m)
            cells.append(" / ".join(f"{v:.2f}" for v in s["rms"]) + f" ({s['gross']})")
        for b in bcols:
            v = bounds[b].get(r)
            cells.append("n/a" if v is None else " / ".join(f"{x:.2f}" for x in v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def reference_lines(cfg: Config, summary: list[dict]) -> list[str]:
    """Published numbers (``[reference]``) beside the measured focal RMS."""
    ref = cfg.reference
    if ref is None:
        return []
    out = []
    for f, v in zip(ref.f, ref.focal_rms):
        for m in cfg.methods:
            s = [x for x in summary if x["method"] == m and x["f"] == f and x["sigma"] == ref.sigma]
            for x in s:
                out.append(f"{m} at sigma {ref.sigma:g} px, f = {f:g}: focal RMS {x['focal_rms']:.2f} % "
                           f"({x['gross']} gross of {x['trials']}); {ref.label}: {v:g} %")
    return out


def records_csv(cfg: Config, records: list[dict]) -> str:
    rows = cfg.rows()
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["row", *SWEEPS, "trial", "seed", "method", "code", "success", "gross", "time_s",
                *[f"{n}_true" for n in NAMES], *NAMES, *[f"err_{n}_pct" for n in NAMES], *[f"std_{n}" for n in NAMES]])
    for rec in records:
        row = rows[rec["row"]]
        base = [rec["row"], *[row[k] for k in SWEEPS], rec["trial"], rec["seed"]]
        if "error" in rec:
            w.writerow(base + ["", "error", False, True, "", *[""] * 16])
            continue
        for m, x in rec["methods"].items():
            est = x.get("estimate", [math.nan] * 4)
            err = x.get("error", [math.nan] * 4)
            std = x.get("std", [math.nan] * 4)
            w.writerow(base + [m, x["code"], x["success"], x["gross"], f"{x['time']:.4f}", *rec["K_true"], *est, *err, *std])
    return buf.getvalue()


# ----------------------------------------------------------------------- figures


def _pick(values, k=4):
    values = list(values)
    if len(values) <= k:
        return values
    idx = sorted({round(i * (len(values) - 1) / (k - 1)) for i in range(k)})
    return [values[i] for i in idx]


def error_figures(cfg: Config, summary: list[dict], bounds: dict | None, out_dir) -> list[str]:
    """``error_vs_<axis>.png`` for every swept numeric axis: focal RMS (% of f) per
    method, one panel per value of the other axes (at most 4), the bound dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = cfg.rows()
    files = []
    for axis in [a for a in cfg.swept() if a in ("f", "sigma", "n_views")]:
        others = [a for a in SWEEPS if a != axis]
        combos = []
        for row in rows:
            key = tuple(row[a] for a in others)
            if key not in combos:
                combos.append(key)
        combos = _pick(combos)
        fig, axs = plt.subplots(1, len(combos), figsize=(4.2 * len(combos), 3.6), squeeze=False)
        for ax, key in zip(axs[0], combos):
            idx = [i for i, row in enumerate(rows) if tuple(row[a] for a in others) == key]
            xs = [rows[i][axis] for i in idx]
            for m in cfg.methods:
                ys = [next(s["focal_rms"] for s in summary if s["row"] == i and s["method"] == m) for i in idx]
                ax.plot(xs, ys, "o-", label=m, ms=3)
            for b, vals in (bounds or {}).items():
                ys = [math.sqrt((vals[i][0] ** 2 + vals[i][1] ** 2) / 2) if vals.get(i) else math.nan for i in idx]
                ax.plot(xs, ys, "k--" if b == "bound" else "k:", label=f"{b} (efficiency)", lw=1)
            ref = cfg.reference
            if ref is not None and axis == "sigma" and key[others.index("f")] in ref.f:
                v = ref.focal_rms[ref.f.index(key[others.index("f")])]
                ax.plot([ref.sigma], [v], "r*", ms=10, label=ref.label)
            ax.set_xlabel({"f": "f (px)", "sigma": "noise sigma (px)", "n_views": "views"}[axis])
            ax.set_ylabel("focal RMS (% of f)")
            ax.set_title(", ".join(f"{a}={'random' if v is None else v}" for a, v in zip(others, key)
                                   if a in cfg.swept() or a == "f"), fontsize=9)
            ax.grid(alpha=0.3)
        axs[0][0].legend(fontsize=7)
        fig.suptitle(f"{cfg.name}: focal error against {axis} (gross failures left out)", fontsize=10)
        fig.tight_layout()
        name = f"error_vs_{axis}.png"
        fig.savefig(out_dir / name, dpi=110)
        plt.close(fig)
        files.append(name)
    return files


def scene_figure(scene, noisy, homologies, out_path, title: str = "") -> None:
    """The views' outlines (exact and one noisy draw) with the true and fitted axis
    ``l_s`` and an arrow towards ``v_x`` (its distance written beside it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    w, h = scene.image_size
    n = len(scene.views)
    fig, axs = plt.subplots(1, n, figsize=(3.6 * n, 3.0), squeeze=False)
    for j, (ax, view) in enumerate(zip(axs[0], scene.views)):
        o = view.outline
        ax.plot(*np.vstack([o, o[:1]]).T, "k-", lw=0.8, label="exact")
        if noisy is not None:
            q = noisy[j]
            ax.plot(*np.vstack([q, q[:1]]).T, "c-", lw=0.5, label="noisy")
        seg = _clip_line(view.l_s, w, h)
        if seg:
            ax.plot(*np.array(seg).T, "g-", lw=1, label="true l_s")
        if homologies is not None:
            seg = _clip_line(np.asarray(homologies[j].l_s), w, h)
            if seg:
                ax.plot(*np.array(seg).T, "m--", lw=1, label="fitted l_s")
        c = o.mean(0)
        v = view.v_x
        d = v[:2] - c * v[2]
        d = d / (np.linalg.norm(d) + 1e-300)
        dist = np.linalg.norm(v[:2] / v[2] - c) if abs(v[2]) > 1e-12 else math.inf
        ax.annotate("", xy=c + 80 * d, xytext=c, arrowprops=dict(arrowstyle="->", color="r"))
        ax.text(*(c + 90 * d), "v_x" + (f" {dist:.0f} px" if math.isfinite(dist) else " at infinity"), color="r", fontsize=7)
        ax.set_xlim(0, w - 1)
        ax.set_ylim(h - 1, 0)
        ax.set_aspect("equal")
        ax.set_title(f"view {j}", fontsize=9)
    axs[0][0].legend(fontsize=6, loc="lower left")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out_path, dpi=110)
    plt.close(fig)
