"""Degenerate geometry and bad input: what the user sees, and the property rates.

Prints, in order:

1. the symmetry residual of true SOR outlines under 2 px of noise against random
   asymmetric blobs (the measurement behind ``sorjax._calibration.ASYMMETRY_PX``);
2. a Markdown table of every bad input and degenerate case tried, with what the user
   sees (exception and message, or result code, details and warnings);
3. how often the weak-geometry warning fires on random scenes with 1 px of noise, and
   the focal errors with and without it;
4. the property rates over many random exact scenes (every profile, upright and lying
   objects, any roll, aspect ratio 0.9 to 1.1, principal point off-centre): noise-free
   recovery of K to 1e-4 of f by the bundle, invariance to the outlines' starting
   point and direction, and the left-right flip (x -> W - 1 - x gives u0 -> W - 1 - u0).

Usage: ``python experiments/degenerate.py [--cases 200] [--quick]`` (``--quick``: 20
property cases, fewer measurements; the full run takes roughly 10 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np

import sorjax
from sorjax import scenes

WIDTH, HEIGHT = 640, 480


# --------------------------------------------------------------------------- scenes


def pose_at(profile, K, el_deg, az_deg, roll=0.0, pix=None, frac=0.5):
    """:func:`sorjax.scenes.pose_at_pixel` for a 480-px-high image."""
    return scenes.pose_at_pixel(profile, K, el_deg, az_deg, roll, pix, fill=frac, image_height=HEIGHT)


def posed_scene(specs, K=None, profile=None):
    K = scenes.intrinsics(800.0, principal_point=(330.0, 250.0)) if K is None else K
    profile = scenes.vase() if profile is None else profile
    return scenes.sor_scene(profile, K, [pose_at(profile, K, *s) for s in specs])


AT_INFINITY = [(30, 0, 0.3), (-10, 70, -0.5), (50, 200, 1.0)]
FINITE = (50, 200, 1.0, (150, 120))
NEAR_AXIS = [(30, 0, 0.3, (340, 260)), (-10, 70, -0.5, (320, 245)), (50, 200, 1.0, (335, 240))]
LEVEL_UPRIGHT = [(0, 0, 0, (200, 250)), (0, 70, 0, (450, 200)), (0, 200, 0, (330, 300))]
MIRROR = [(0, 0, 0), (20, 90, 0)]
GOOD = [(30, 0, 0.3, (150, 150)), (-10, 70, -0.5, (480, 350)), (50, 200, 1.0, (200, 380))]


def blob(seed, R=120.0, amp=0.35, n=1500, centre=(320.0, 240.0)):
    """A smooth random closed curve that is not symmetric (harmonics 2..6 of the radius)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = np.ones_like(t)
    for k in range(2, 7):
        r += rng.uniform(0.5, 1.0) * amp / (k - 1) * np.cos(k * t + rng.uniform(0, 2 * np.pi))
    return np.stack([centre[0] + R * r * np.cos(t), centre[1] + R * r * np.sin(t)], 1)


def ellipse(a=90.0, b=60.0, c=(300.0, 200.0), phase=0.3, n=800):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([c[0] + a * np.cos(t + phase), c[1] + b * np.sin(t)], 1)


def sphere_outline(K, R, t, centre, radius, n=800):
    """Exact outline of a sphere (an ellipse): rays from the image of the centre to the conic."""
    P = scenes.camera_matrix(K, R, t)
    C = scenes.sphere_image_conic(P, centre, radius)
    x0 = P @ np.append(centre, 1.0)
    x0 = x0[:2] / x0[2]
    pts = []
    for th in np.linspace(0, 2 * np.pi, n, endpoint=False):
        d = np.array([math.cos(th), math.sin(th), 0.0])
        c = np.append(x0, 1.0)
        A, B, Cc = d @ C @ d, 2 * c @ C @ d, c @ C @ c
        s = (-B + math.sqrt(B * B - 4 * A * Cc)) / (2 * A)
        s = s if s > 0 else (-B - math.sqrt(B * B - 4 * A * Cc)) / (2 * A)
        pts.append(x0 + s * d[:2])
    return np.array(pts)


def bitten(outline, frac=0.4):
    """An outline with a dent on one side (an occlusion)."""
    c = outline.mean(0)
    r = np.linalg.norm(outline - c, axis=1).mean()
    i = int(np.argmax(outline[:, 0]))
    near = np.linalg.norm(outline - outline[i], axis=1) < frac * r
    o = outline.copy()
    o[near] = c + (outline[near] - c) * 0.8
    return o


# ------------------------------------------------------------------ what users see


def code_name(cal) -> str:
    for name, item in sorjax.RESULTS._name_to_item.items():
        if bool(cal.result == item):
            return name
    return "?"


def what_user_sees(fn):
    """Run ``fn`` (a calibrate call); return a one-cell description and the result."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            cal = fn()
        except Exception as e:  # noqa: BLE001 - we report whatever the user would see
            return f"**{type(e).__name__}**: {e}", None
    parts = [f"result `{code_name(cal)}`"]
    if cal.success:
        parts.append("K = (fu, fv, u0, v0) = (" + ", ".join(f"{x:.1f}" for x in (cal.fu, cal.fv, cal.u0, cal.v0)) + ")")
        if np.all(np.isfinite(cal.std)):
            parts.append("std = (" + ", ".join(f"{x:.2g}" for x in cal.std) + ") px")
    else:
        parts.append("K = (" + ", ".join("NaN" if not np.isfinite(x) else f"{x:.1f}" for x in (cal.fu, cal.fv, cal.u0, cal.v0)) + ")")
        parts.append(f"message: {cal.message}")
    if cal.dropped:
        parts.append(f"used views {cal.used}")
    for w in caught:
        parts.append(f"warning: {w.message}")
    return "; ".join(parts), cal


def cases():
    """(group, case, thunk) for every bad input and degenerate case tried."""
    o0, o1, o2 = posed_scene(GOOD).outlines
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    eight = np.stack([100 * np.sin(t), 60 * np.sin(2 * t)], 1) + 300
    nan = o1.copy()
    nan[7] = np.nan
    inf = o1.copy()
    inf[3, 0] = np.inf
    touch = np.vstack([o1[:300], o1[100:101], o1[300:]])
    cal = sorjax.calibrate
    bad = [
        ("no outlines", lambda: cal([])),
        ("one outline (in a list)", lambda: cal([o0])),
        ("one outline, not in a list", lambda: cal(o0)),
        ("one OpenCV contour (N, 1, 2), not in a list", lambda: cal(o0[:, None, :])),
        ("a file name instead of outlines", lambda: cal("view0.txt")),
        ("None", lambda: cal(None)),
        ("a dict of outlines", lambda: cal({"a": o0, "b": o1})),
        ("a number", lambda: cal(5)),
        ("NaN in an outline", lambda: cal([o0, nan])),
        ("inf in an outline", lambda: cal([o0, inf])),
        ("an empty outline", lambda: cal([o0, np.zeros((0, 2))])),
        ("5 points", lambda: cal([o0, o1[::400][:5]])),
        ("all points equal", lambda: cal([o0, np.ones((50, 2))])),
        ("open curve (half an outline)", lambda: cal([o0, o1[: len(o1) // 2]])),
        ("self-intersecting (figure eight)", lambda: cal([o0, eight])),
        ("outline traced twice", lambda: cal([o0, np.vstack([o1, o1])])),
        ("a point visited twice (curve touches itself)", lambda: cal([o0, touch])),
        ("collinear points (no area)", lambda: cal([o0, np.stack([np.linspace(0, 100, 30)] * 2, 1)])),
        ("normalised coordinates (0..1)", lambda: cal([o0 / 640, o1 / 640])),
        ("shape (N, 3)", lambda: cal([o0, np.hstack([o1, o1[:, :1]])])),
        ("transposed (2, N)", lambda: cal([o0, o1.T])),
        ("1-D array", lambda: cal([o0, o1[:, 0]])),
        ("dtype str", lambda: cal([o0, o1.astype(str)])),
        ("dtype complex", lambda: cal([o0, o1.astype(complex)])),
        ("dtype bool", lambda: cal([o0, o1 > 300])),
        ("ragged list", lambda: cal([o0, [[1, 2], [3]]])),
        ("list with None", lambda: cal([o0, None])),
        ("list with a string", lambda: cal([o0, "abc"])),
        ("method='III'", lambda: cal([o0, o1], method="III")),
        ("aspect_ratio=-1", lambda: cal([o0, o1], method="IIb", aspect_ratio=-1.0)),
        ("aspect_ratio with IIa", lambda: cal([o0, o1], method="IIa", aspect_ratio=1.1)),
        ("n_samples=0", lambda: cal([o0, o1], n_samples=0)),
        ("n_points=10", lambda: cal([o0, o1], n_points=10)),
        ("homologies of the wrong length", lambda: cal([o0, o1], homologies=[1])),
        ("homologies not Homology", lambda: cal([o0, o1], homologies=[1, 2])),
    ]
    for name, fn in bad:
        yield "bad input", name, fn

    K = scenes.intrinsics(800.0, principal_point=(330.0, 250.0))
    inf_sc = posed_scene(AT_INFINITY, K)
    paper = lambda outs, s=1.0: [scenes.paper_noise(o, s, 10 + i) for i, o in enumerate(outs)]  # noqa: E731
    gauss = lambda outs, s=1.0: [scenes.gaussian_noise(o, s, 10 + i) for i, o in enumerate(outs)]  # noqa: E731
    prof = scenes.vase()
    R, tt = pose_at(prof, K, 20, 40, 0.2, (200, 180))
    sphere = sphere_outline(K, R, tt, np.array([0.0, 0.15, 0.0]), 0.08)
    mixed = posed_scene(AT_INFINITY[:2] + [FINITE], K)
    mirror = posed_scene(MIRROR + [FINITE], K)
    level = posed_scene(LEVEL_UPRIGHT, K)
    near = posed_scene(NEAR_AXIS, K)
    good = posed_scene(GOOD, K)
    tele = posed_scene(GOOD, scenes.intrinsics(3000.0, principal_point=(330.0, 250.0)))
    geo = [
        ("sphere outline + 2 SOR views", lambda: cal([o0, sphere, o1])),
        ("ellipse + 1 SOR view", lambda: cal([o0, ellipse()])),
        ("ellipse + 1 SOR view, throw=True", lambda: cal([o0, ellipse()], throw=True)),
        ("random blob + 2 SOR views", lambda: cal([o0, o1, blob(1)])),
        ("2 random blobs + 1 SOR view", lambda: cal([o0, blob(1), blob(2)])),
        ("occluded (dented) SOR view + 2 SOR views", lambda: cal([o0, o1, bitten(o2)])),
        ("the same view twice", lambda: cal([o0, o0.copy()])),
        ("every v_x at infinity (object at the principal point), bundle", lambda: cal(inf_sc.outlines)),
        ("every v_x at infinity, Method I", lambda: cal(inf_sc.outlines, method="I")),
        ("every v_x at infinity, IIa", lambda: cal(inf_sc.outlines, method="IIa")),
        ("every v_x at infinity, IIb", lambda: cal(inf_sc.outlines, method="IIb")),
        ("every v_x at infinity, paper noise 1 px", lambda: cal(paper(inf_sc.outlines))),
        ("every v_x at infinity, throw=True", lambda: cal(inf_sc.outlines, throw=True)),
        ("every v_x at infinity, i.i.d. Gaussian 1 px at 0.3 px spacing (known limitation)",
         lambda: cal(gauss(inf_sc.outlines))),
        ("two v_x at infinity + one finite", lambda: cal(mixed.outlines)),
        ("two mirror-symmetric views (v_x at infinity) + one finite, free aspect", lambda: cal(mirror.outlines)),
        ("same, aspect_ratio=1", lambda: cal(mirror.outlines, aspect_ratio=1.0)),
        ("upright objects, level camera (parallel imaged axes), free aspect", lambda: cal(level.outlines)),
        ("same, aspect_ratio=1", lambda: cal(level.outlines, aspect_ratio=1.0)),
        ("same, paper noise 1 px, free aspect", lambda: cal(paper(level.outlines))),
        ("object within 10 px of the principal point in every view (v_x far)", lambda: cal(near.outlines)),
        ("same, paper noise 1 px", lambda: cal(paper(near.outlines))),
        ("same, paper noise 1 px, IIb", lambda: cal(paper(near.outlines), method="IIb")),
        ("weak perspective (f = 3000 px), exact", lambda: cal(tele.outlines)),
        ("weak perspective (f = 3000 px), paper noise 1 px", lambda: cal(paper(tele.outlines))),
        ("good configuration, paper noise 1 px (reference)", lambda: cal(paper(good.outlines))),
    ]
    for name, fn in geo:
        yield "degenerate geometry", name, fn


def print_table():
    print("\n## What the user sees\n")
    print("| # | group | case | what the user sees |")
    print("|---|---|---|---|")
    for k, (group, name, fn) in enumerate(cases(), 1):
        seen, _ = what_user_sees(fn)
        seen = seen.replace("|", "\\|").replace("\n", " ")
        print(f"| {k} | {group} | {name} | {seen} |", flush=True)


# ------------------------------------------------------------------ measurements


def residual_study(n_scenes: int, n_blobs: int):
    """Per-view RMS symmetry residual: true SORs with 2 px of noise vs random blobs."""
    print("\n## Symmetry residual: SOR outlines with 2 px of noise vs asymmetric blobs (px)\n")
    res = {"SOR exact": [], "SOR paper noise 2 px": [], "SOR Gaussian 2 px": []}
    for seed in range(n_scenes):
        sc = scenes.random_sor_scene(1000 + seed, 2)
        for i, o in enumerate(sc.outlines):
            for key, oo in (("SOR exact", o), ("SOR paper noise 2 px", scenes.paper_noise(o, 2.0, seed * 7 + i)),
                            ("SOR Gaussian 2 px", scenes.gaussian_noise(o, 2.0, seed * 7 + i))):
                try:
                    res[key].append(float(sorjax.fit_homology(oo).rms))
                except ValueError:
                    pass  # noise can make an outline cross itself
    for amp in (0.2, 0.35):
        res[f"blob amp {amp}"] = [float(sorjax.fit_homology(blob(s, amp=amp)).rms) for s in range(n_blobs)]
    print("| outlines | n | median | 95 % | max | > 2 px |")
    print("|---|---|---|---|---|---|")
    for key, v in res.items():
        v = np.asarray(v)
        print(f"| {key} | {len(v)} | {np.median(v):.3g} | {np.percentile(v, 95):.3g} | {v.max():.3g} | {np.mean(v > 2.0):.0%} |")


def weak_warning_study(n: int):
    """How often the weak-geometry warning fires with 1 px of noise, and the errors."""
    print(f"\n## Weak-geometry warning on {n} random 3-view scenes, paper noise 1 px\n")
    rows = []
    for seed in range(n):
        sc = scenes.random_sor_scene(2000 + seed, 3)
        outs = [scenes.paper_noise(o, 1.0, seed * 3 + i) for i, o in enumerate(sc.outlines)]
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            cal = sorjax.calibrate(outs, outline_error=0.0)
        warned = any("weak geometry" in str(w.message) for w in caught)
        if cal.success:
            err = abs(cal.fv - sc.K[1, 1]) / sc.K[1, 1]
            rows.append((warned, err, cal.std[1] / sc.K[1, 1]))
        else:
            rows.append((None, np.nan, np.nan))
    rows_ok = [r for r in rows if r[0] is not None]
    print("| | n | median focal error | 90 % focal error | median reported std |")
    print("|---|---|---|---|---|")
    for label, sel in (("warned", True), ("not warned", False)):
        e = np.array([r[1] for r in rows_ok if r[0] == sel])
        s = np.array([r[2] for r in rows_ok if r[0] == sel])
        if len(e):
            print(f"| {label} | {len(e)} | {np.median(e):.2%} | {np.percentile(e, 90):.2%} | {np.median(s):.2%} |")
    print(f"| not successful | {sum(r[0] is None for r in rows)} | | | |")


def random_camera(rng):
    f = rng.uniform(500.0, 1500.0)
    a = rng.uniform(0.9, 1.1)
    pp = (WIDTH * (0.5 + rng.uniform(-0.1, 0.1)), HEIGHT * (0.5 + rng.uniform(-0.1, 0.1)))
    return scenes.intrinsics(f, aspect_ratio=a, principal_point=pp)


def k_error(cal, K) -> float:
    est = np.array([cal.fu, cal.fv, cal.u0, cal.v0])
    return float(np.max(np.abs(est - np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]]))) / K[1, 1])


def property_rates(n: int, n_extra: int, tol: float = 1e-4):
    print(f"\n## Property rates on random exact scenes (tolerance {tol:g} of f, bundle, 3 views)\n")
    names = sorted(scenes.PROFILES)
    rec, inv, flip, fails, shape = [], [], [], [], []
    t0 = time.perf_counter()
    for k in range(n):
        rng = np.random.default_rng(5000 + k)
        K = random_camera(rng)
        sc = scenes.random_sor_scene(int(rng.integers(2**31)), 3, K=K, shapes=[names[k % len(names)]], lying=True)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cal = sorjax.calibrate(sc.outlines, outline_error=0.0)
            ok = cal.success and k_error(cal, K) < tol
            rec.append(ok)
            shape.append(names[k % len(names)])
            if not ok:
                fails.append((k, code_name(cal), k_error(cal, K), sc.description))
            if k < n_extra:
                outs = [np.roll(o, int(rng.integers(len(o))), 0) for o in sc.outlines]
                outs = [o[::-1] if rng.uniform() < 0.5 else o for o in outs]
                c2 = sorjax.calibrate(outs, outline_error=0.0)
                inv.append(bool(c2.success and k_error(c2, K) < tol and cal.success
                                and np.max(np.abs(np.asarray(c2.K) - np.asarray(cal.K))) < tol * K[1, 1]))
                fl = []
                for o in sc.outlines:
                    o = o.copy()
                    o[:, 0] = WIDTH - 1 - o[:, 0]
                    fl.append(o)
                Kf = K.copy()
                Kf[0, 2] = WIDTH - 1 - K[0, 2]
                c3 = sorjax.calibrate(fl, outline_error=0.0)
                flip.append(bool(c3.success and k_error(c3, Kf) < tol))
    dt = time.perf_counter() - t0
    print("| property | cases | rate |")
    print("|---|---|---|")
    print(f"| noise-free recovery of K within {tol:g} f | {len(rec)} | {np.mean(rec):.1%} |")
    print(f"| invariance to start point and direction | {len(inv)} | {np.mean(inv):.1%} |")
    print(f"| left-right flip gives the flipped K | {len(flip)} | {np.mean(flip):.1%} |")
    for nm in names:
        r = [ok for ok, s in zip(rec, shape) if s == nm]
        print(f"| recovery, {nm} only | {len(r)} | {np.mean(r):.1%} |")
    print(f"\n({dt:.0f} s)")
    for k, code, err, desc in fails:
        print(f"- case {k}: {code}, error {err:.2e} f: {desc}")
    return float(np.mean(rec))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=200, help="random scenes for the recovery rate (>= 100)")
    ap.add_argument("--quick", action="store_true", help="small numbers everywhere (a smoke run)")
    ap.add_argument("--skip-table", action="store_true")
    args = ap.parse_args()
    n = 20 if args.quick else args.cases
    if not args.quick:
        residual_study(12, 20)
    if not args.skip_table:
        print_table()
    if not args.quick:
        weak_warning_study(30)
    property_rates(n, min(n, 10 if args.quick else 40))


if __name__ == "__main__":
    main()
