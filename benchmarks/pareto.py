#!/usr/bin/env python
"""Speed against accuracy: every method and setting as a point (run time, |stiffness error|), Pareto fronts.

Usage::

    python benchmarks/pareto.py --quick                  # 700 particles, fewer settings
    python benchmarks/pareto.py                          # 3000 particles, every setting (the full run)
    python benchmarks/pareto.py --cases bonds --n 2000

Case types (one random box each, ``jaxbpm.generate.box(n, seed=0, packing_fraction=0.55).largest_cluster()``, bond
E = 1e9 Pa, nu = 0.25; uniaxial compression between clamped layers):

* ``bonds``: bonds only, strain 0.002.
* ``hertz``: Hertz(-Mindlin) contacts superimposed on the bonds (``bond_contact="superimpose"``), stiffer particles
  (particle E = 1e10 Pa, nu = 0.25, friction 0.5, restitution 0.5), strain 0.01, so that the contacts carry a
  visible part of the load (``contact_share`` in the JSON: K with contacts / K bonds only - 1, by the reference).

Points (each one ``jaxbpm.solve`` call; run time = the library's ``run_time``, compilation excluded; error =
|K / K_ref - 1|):

* DEM: time-step safety factor x loading duration (``safety`` in {0.9, 0.5, 0.25}, ``transits`` in {10, 20, 40, 80}
  elastic-wave crossings, i.e. loading rates 8:4:2:1; the defaults are 0.5 and 40), local damping 0.7, a fixed
  chunk of 50 steps (the jitted chunk compiles once per case; runs are rounded up to whole chunks at the same loading
  rate, the fit only uses the loading up to the target strain). ``--quick``: transits {10, 40}.
* DSM linear (in the ``hertz`` case with the contacts linearised, two passes, the library's default for
  ``nonlinear=False`` on a scene with contacts): CG relative residual ``linear_tol``
  1e-2 ... 1e-8 (6 DOF), ``stiffness_tol`` 1e-2 / 1e-3 / 1e-4 (stop once the strain energy settles; with
  ``linear_tol`` 1e-10), 3 DOF (translations only), block-Jacobi preconditioner instead of the two-level one.
* DSM nonlinear (Newton-Krylov, 4 load steps, contacts sliding at the Coulomb limit (the library's default),
  contact candidates fixed at rest, K fitted over the same
  range as the DEM's): Newton tolerance ``tol`` 1e-2, 1e-3, 1e-4, 1e-6, 1e-8 (``--quick``: bonds 1e-2, 1e-4; hertz
  1e-2, 1e-3), ``stiffness_tol`` 1e-3 (full run also 1e-2), 3 DOF (full run). In the ``bonds`` case it solves the
  geometrically nonlinear static problem of the bonds alone. With contacts Newton can stall near a relative residual
  of 1e-5 (measured without slip, 700 particles, strain 0.01: ``tol=1e-5`` ran 30 Newton iterations per load
  step, 112 s, and stopped unconverged), so the ``hertz`` points below 1e-4 are capped at ``newton_maxiter=10``
  and drawn hollow when they miss their tolerance. It compiles inside every call; run time excludes that. The library's ``run_time`` of the
  nonlinear DSM leaves out its starting point (a linear bond solve, run together with the compilation); the run
  time used here adds it back, measured as a linear DSM call with the same DOFs and CG tolerance
  (``run_s_library`` and ``start_solve_s`` in the JSON).
* STE: ``dofs`` 3 / 6 x ``first_neighbour`` False / True, ``surface_depth`` 0 and two mean diameters (default: one
  diameter); 3 DOF in single precision (``precision="float32"``, default and zero surface depth); ``hertz``:
  contacts linearised at the default point (middle of the fit range) and, full run only, at ``contact_fraction``
  0.25 and 1.0.

References:

* ``bonds``: the nonlinear DSM at Newton tolerance 1e-10 (CG 1e-12) -- the static equilibrium of the same
  (co-rotational, geometrically nonlinear) bond model the DEM integrates, with the stiffness fitted over the same
  part of the loading as the DEM's; the DEM converges to it as the loading slows down and the linear DSM differs
  from it only by geometric nonlinearity at 0.2 % strain. The most careful DEM setting is run too, and its distance
  to the reference is reported (``reference_check``).
* ``hertz``: the most careful DEM setting (``safety`` 0.25, ``transits`` 160): the static DSM assumes no slip and
  contact candidates fixed at rest, so it is not a reference there. The DEM at ``safety`` 0.25, ``transits`` 80 is
  its check (how far the reference itself may be from the quasi-static limit).

A call that raises is recorded as a failed point (its error message in the JSON, listed under the plot), not
fatal. JSON to ``results/pareto.json`` (``--quick``: ``results/pareto_quick.json``); one log-log PNG per case
(``results/pareto_<case>.png``; ``--quick``: ``results/pareto_quick_<case>.png``): x run time, y |error|, points
labelled, the Pareto front (no point both faster and more accurate) as a step line. Errors below 1e-7 are drawn at
1e-7 (triangles); hollow markers: solves that missed their tolerance (``converged`` False).

Measured (``--quick``, ``time python benchmarks/pareto.py --quick``, 2-core CPU shared with other jobs, load
average 7-9 during the run): real 4m39s, user 2m13s (698 particles, 1899 bonds; 26 points per case). The slowest
parts: the DEM reference with contacts (13 s run + 11 s compile) and the three nonlinear DSM points with contacts
(10-21 s run each, 20 s compile for the first).

Full run (``python benchmarks/pareto.py --threads 1``, 2994 particles, one core): 12 min, most of it in the
careful DEM references and the nonlinear DSM with contacts. Fronts: bonds only -- STE 3 DOF first neighbour / default
/ surface 0 (2.9-6.9 ms, +27 / +17 / +3.5 %), linear DSM stiffness_tol 1e-2 (31 ms, +0.18 %) and tighter tolerances
(~0.1 %), nonlinear DSM tol 1e-2 / 1e-3 / 1e-8 (0.13 / 0.32 / 1.5 s, +0.036 % / 8e-6 % / 4e-12 %); the careful DEM
(safety 0.25, 160 transits) is -0.004 % from the reference. Hertz contacts at 1 % strain (contacts add 88 % to K)
-- STE 3 DOF variants (4-10 ms, +24 % to +81 %), the linear DSM with linearised contacts (0.22-0.49 s, -4.0 % to
-4.9 %; bonds only it would be -47 %), DEM safety 0.9 / 10 transits (0.96 s, -0.29 %), 20 transits (1.8 s,
-0.016 %), 40 (3.6 s, -0.004 %), the nonlinear DSM (sliding contacts) -0.10 % in 1.6-4.8 s, off the front: the
DEM reaches 0.02 % sooner here.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
import warnings

from _common import enable_x64, machine_info, pin_threads, table, write_json

CASES = ("bonds", "hertz")
ERR_FLOOR = 1e-7


def log(msg):
    print(msg, file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------------------- samples
def make_sample(case, args):
    import jaxbpm

    kw = dict(seed=args.seed, packing_fraction=args.packing_fraction, materials={"E": 1e9, "nu": 0.25})
    if case == "hertz":
        kw["particle_material"] = {"E": args.particle_E, "nu": 0.25, "density": 2500.0, "friction": 0.5,
                                   "restitution": 0.5}
        kw["bond_contact"] = "superimpose"
    return jaxbpm.generate.box(args.n, **kw).largest_cluster()


def settings(case, args, diameter):
    """``(group, label, method, options)`` for every point of ``case``; the reference first."""
    quick = args.quick
    pts = []
    if case == "bonds":
        pts.append(("reference", "DSM nonlin tol 1e-10", "dsm", dict(nonlinear=True, tol=1e-10, linear_tol=1e-12)))
        pts.append(("DEM", "DEM s0.25 t160", "dem", dict(safety=0.25, transits=160.0)))
    else:
        pts.append(("reference", "DEM s0.25 t160", "dem", dict(safety=0.25, transits=160.0)))
        pts.append(("DEM", "DEM s0.25 t80", "dem", dict(safety=0.25, transits=80.0)))
    transits = (10.0, 40.0) if quick else (10.0, 20.0, 40.0, 80.0)
    for s in (0.9, 0.5, 0.25):
        for t in transits:
            if (s, t) != (0.25, 80.0):
                pts.append(("DEM", f"DEM s{s:g} t{t:g}", "dem", dict(safety=s, transits=t)))
    tols = (1e-2, 1e-3, 1e-4, 1e-6, 1e-8) if quick else (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)
    lin = dict(nonlinear=False)
    for tol in tols:
        pts.append(("DSM linear", f"DSM lin tol {tol:.0e}", "dsm", dict(lin, linear_tol=tol)))
    for st in ((1e-2, 1e-3) if quick else (1e-2, 1e-3, 1e-4)):
        pts.append(("DSM linear", f"DSM lin stol {st:.0e}", "dsm", dict(lin, linear_tol=1e-10, stiffness_tol=st)))
    pts.append(("DSM linear", "DSM lin 3DOF tol 1e-6", "dsm", dict(lin, dofs=3, linear_tol=1e-6)))
    if not quick:
        pts.append(("DSM linear", "DSM lin 3DOF tol 1e-3", "dsm", dict(lin, dofs=3, linear_tol=1e-3)))
    pts.append(("DSM linear", "DSM lin jacobi tol 1e-6", "dsm", dict(lin, linear_tol=1e-6, preconditioner="jacobi")))
    ntols = (1e-2, 1e-4) if quick else (1e-2, 1e-3, 1e-4, 1e-6, 1e-8)
    if case == "hertz" and quick:
        ntols = (1e-2, 1e-3)
    for tol in ntols:
        o = dict(nonlinear=True, tol=tol)
        if case == "hertz" and tol < 1e-4:
            o["newton_maxiter"] = 10  # with contacts Newton stalls near 1e-5 (see the module docstring)
        pts.append(("DSM nonlinear", f"DSM nonlin tol {tol:.0e}", "dsm", o))
    if case == "hertz" or not quick:
        pts.append(("DSM nonlinear", "DSM nonlin stol 1e-3", "dsm", dict(nonlinear=True, tol=1e-8,
                                                                        stiffness_tol=1e-3)))
    if not quick:
        pts.append(("DSM nonlinear", "DSM nonlin 3DOF tol 1e-3", "dsm", dict(nonlinear=True, dofs=3, tol=1e-3)))
    if not quick:
        pts.append(("DSM nonlinear", "DSM nonlin stol 1e-2", "dsm", dict(nonlinear=True, tol=1e-8,
                                                                        stiffness_tol=1e-2)))
    for dofs in (3, 6):
        for fn in (False, True):
            pts.append(("STE", f"STE {dofs}DOF" + (" 1st-nb" if fn else ""), "ste",
                        dict(dofs=dofs, first_neighbour=fn)))
        pts.append(("STE", f"STE {dofs}DOF surf 0", "ste", dict(dofs=dofs, surface_depth=0.0)))
        pts.append(("STE", f"STE {dofs}DOF surf 2d", "ste", dict(dofs=dofs, surface_depth=2.0 * diameter)))
    pts.append(("STE", "STE 3DOF float32", "ste", dict(dofs=3, precision="float32")))
    pts.append(("STE", "STE 3DOF surf 0 float32", "ste", dict(dofs=3, surface_depth=0.0, precision="float32")))
    if case == "hertz" and not quick:
        for cf in (0.25, 1.0):
            pts.append(("STE", f"STE 3DOF cf {cf:g}", "ste", dict(dofs=3, contact_fraction=cf)))
    return pts


# ---------------------------------------------------------------------------------------------------- one point
def run_point(sample, scene, method, opts, repeats):
    import jaxbpm

    calls = 1 if method == "dem" or opts.get("nonlinear") else repeats
    opts = dict(opts)
    if method == "dem":
        opts.setdefault("chunk", 50)
    t = time.perf_counter()
    res = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(calls):
            res.append(jaxbpm.solve(sample, scene, method, **opts))
    wall = time.perf_counter() - t
    r = min(res, key=lambda x: x.run_time)
    rec = {"K": float(r.stiffness), "run_s": float(r.run_time), "compile_s": float(res[0].compile_time),
           "wall_s": wall, "calls": calls, "warnings": sorted({str(w.message)[:200] for w in caught})}
    if method == "dsm" and opts.get("nonlinear"):
        # the library times the Newton iterations only: its starting point, a linear bond solve, is run with the
        # compilation and counted there. It is part of the method's cost, so its run time (the same linear solve,
        # measured as a linear DSM call with the same DOFs and CG tolerance) is added.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            start = jaxbpm.solve(sample, dataclasses.replace(scene, contacts=False), "dsm", nonlinear=False,
                                 dofs=opts.get("dofs"), linear_tol=opts.get("linear_tol", 1e-6))
        rec.update(run_s_library=rec["run_s"], start_solve_s=float(start.run_time))
        rec["run_s"] = rec["run_s_library"] + rec["start_solve_s"]
    st = r.stats
    if method == "dem":
        rec.update(dt=st["dt"], dt_crit=st.get("dt_crit"), steps=st["steps"], loading_time=st["loading_time"])
    elif method == "dsm":
        rec.update(converged=bool(st["converged"]), iterations=st.get("iterations"), residual=st.get("residual"),
                   newton_iterations=st.get("newton_iterations"), dofs=st.get("dofs"))
    else:
        rec.update(skipped_particles=st["skipped"], surface_particles=st["surface"], contacts=st.get("contacts"))
    return rec


def pareto_front(points):
    """The points no other point beats in both run time and error (sorted by run time;
    :func:`jaxbpm.plots.pareto_front`: a 1 % smaller error counts, ties within that do not)."""
    from jaxbpm.plots import pareto_front as front

    ok = [p for p in points if p.get("abs_error") is not None]
    return [ok[i] for i in front([p["run_s"] for p in ok], [p["abs_error"] for p in ok], tie=1e-2)]


def plot(case, data, path, note):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxbpm.io import atomic_write

    colours = {"DEM": "C3", "DSM linear": "C0", "DSM nonlinear": "C4", "STE": "C2", "reference": "k"}
    fig, ax = plt.subplots(figsize=(10, 7))
    pts = [p for p in data["points"] if p.get("abs_error") is not None and p["run_s"] > 0]
    seen = set()
    for k, p in enumerate(pts):
        y = max(p["abs_error"], ERR_FLOOR)
        g = p["group"]
        mk = "*" if g == "reference" else ("v" if p["abs_error"] < ERR_FLOOR else "o")
        ax.loglog(p["run_s"], y, mk, color=colours[g], mec="k", mew=0.5, ms=11 if mk == "*" else 6,
                  mfc="none" if p.get("converged") is False else colours[g],
                  label=None if g in seen else (f"{g} ({p['label']})" if g == "reference" else g))
        seen.add(g)
        ax.annotate(p["label"], (p["run_s"], y), xytext=(4, 3 if k % 2 else -8), textcoords="offset points",
                    fontsize=5.5, color=colours[g])
    front = [p for p in data["front"] if p["run_s"] > 0]
    if front:
        xs = [p["run_s"] for p in front]
        ys = [max(p["abs_error"], ERR_FLOOR) for p in front]
        ax.step(xs + [ax.get_xlim()[1]], ys + [ys[-1]], where="post", color="0.3", lw=1.2, alpha=0.8,
                label="Pareto front")
    ax.set_xlabel("run time [s] (compilation excluded)")
    ax.set_ylabel("|K / K_ref - 1|")
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=8, loc="lower left")
    ref = data["reference"]
    ax.set_title(f"Speed against accuracy, case '{case}': {data['particles']} particles, {data['bonds']} bonds, "
                 f"strain {data['strain']:g}\nreference: {ref['label']} (K = {ref['K']:.6g} N/m)", fontsize=10)
    failed = [p for p in data["points"] if "error_message" in p]
    if failed:
        note = note + "\nfailed: " + "; ".join(f"{p['label']}: {p['error_message'][:80]}" for p in failed)
    fig.text(0.01, 0.005, note, fontsize=6, alpha=0.8)
    fig.tight_layout(rect=(0, 0.04 + 0.015 * len(failed), 1, 1))
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=130, format="png"))
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------------------- main
def run_case(case, args):
    import numpy as np

    import jaxbpm

    t = time.perf_counter()
    sample = make_sample(case, args)
    gen = time.perf_counter() - t
    strain = args.strain if case == "bonds" else args.hertz_strain
    scene = jaxbpm.scenes.UniaxialCompression(strain=strain, contacts=case == "hertz")
    diameter = 2.0 * float(np.mean(np.asarray(sample.radii)))
    log(f"== case {case}: {sample.n_particles} particles, {sample.n_bonds} bonds, strain {strain} "
        f"(generated in {gen:.1f} s)")
    points = []
    for group, label, method, opts in settings(case, args, diameter):
        p = {"group": group, "label": label, "method": method, "options": opts}
        try:
            p.update(run_point(sample, scene, method, opts, args.repeats))
        except Exception as exc:  # a failed point, not fatal
            p["error_message"] = f"{type(exc).__name__}: {exc}"
            log(f"  {label:28s} FAILED {p['error_message'][:300]}")
            points.append(p)
            continue
        log(f"  {label:28s} K={p['K']:.7g}  run {p['run_s']:.4g} s  compile {p['compile_s']:.3g} s"
            + ("" if p.get("converged", True) else "  (not converged)"))
        points.append(p)
    ref = points[0]
    if "K" not in ref:
        raise RuntimeError(f"the reference of case {case} failed: {ref['error_message']}")
    for p in points:
        if "K" in p:
            p["signed_error"] = p["K"] / ref["K"] - 1
            p["abs_error"] = abs(p["signed_error"])
    check = points[1]
    front = pareto_front(points[1:])
    for p in points:
        p["on_front"] = any(p is f for f in front)
    out = {"case": case, "particles": sample.n_particles, "bonds": sample.n_bonds, "strain": strain,
           "generate_s": gen, "scene": f"UniaxialCompression(strain={strain}, contacts={case == 'hertz'})",
           "reference": {"label": ref["label"], "K": ref["K"], "run_s": ref["run_s"], "options": ref["options"]},
           "reference_check": {"label": check["label"], "signed_error": check.get("signed_error")},
           "points": points, "front": [{k: f[k] for k in ("label", "run_s", "abs_error")} for f in front]}
    if case == "hertz":
        # the bonds alone (the linear DSM points linearise the contacts of this scene)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bonds_only = jaxbpm.solve(sample, dataclasses.replace(scene, contacts=False), "dsm", linear_tol=1e-8)
        out["contact_share"] = ref["K"] / bonds_only.stiffness - 1
    return out


def replot(path) -> int:
    import json

    with open(path) as f:
        out = json.load(f)
    for case, d in out["cases"].items():
        front = pareto_front(d["points"][1:])
        labels = {f["label"] for f in front}
        for p in d["points"][1:]:
            p["on_front"] = p["label"] in labels
        d["front"] = [{k: f[k] for k in ("label", "run_s", "abs_error")} for f in front]
    for r in out["rows"]:
        d = out["cases"][r["case"]]
        r["front"] = "*" if any(p["label"] == r["point"] and p.get("on_front") for p in d["points"]) else ""
    write_json(path, out)
    m = out["machine"]
    note = f"{m['device']} ({m['cpu_count']} cores), jax {m['jax']}, float64, seed {out['settings']['seed']}"
    stem = os.path.splitext(path)[0]
    for case, d in out["cases"].items():
        print(f"wrote {plot(case, d, f'{stem}_{case}.png', note)}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=3000, help="particles per sample (before largest_cluster)")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    ap.add_argument("--strain", type=float, default=0.002, help="strain of the bonds case")
    ap.add_argument("--hertz-strain", type=float, default=0.01, help="strain of the hertz case")
    ap.add_argument("--particle-E", type=float, default=1e10, help="particle (contact) E of the hertz case [Pa]")
    ap.add_argument("--packing-fraction", type=float, default=0.55)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=1, help="calls per linear DSM / STE point (min run time)")
    ap.add_argument("--threads", type=int, default=None, help="restrict to this many cores")
    ap.add_argument("--quick", action="store_true", help="700 particles, fewer settings")
    ap.add_argument("--out", default="results/pareto.json")
    ap.add_argument("--replot", action="store_true",
                    help="no runs: recompute the fronts of --out and redraw its PNGs")
    args = ap.parse_args(argv)
    if args.quick:
        args.n = min(args.n, 700)
        if args.out == "results/pareto.json":
            args.out = "results/pareto_quick.json"
    if args.replot:
        return replot(args.out)
    pin_threads(args.threads)
    enable_x64()
    t0 = time.perf_counter()
    cases = {case: run_case(case, args) for case in args.cases}
    rows = []
    for case, d in cases.items():
        for p in d["points"]:
            rows.append({"case": case, "point": p["label"], "run_s": p.get("run_s", ""),
                         "compile_s": p.get("compile_s", ""), "K": p.get("K", ""),
                         "error_%": 100 * p["signed_error"] if "signed_error" in p else "FAILED",
                         "front": "*" if p.get("on_front") else "",
                         "note": ("not converged" if p.get("converged") is False else "")
                         + (p["error_message"][:60] if "error_message" in p else "")})
    print("\nSpeed against accuracy (error: K / K_ref - 1; front: on the Pareto front of run time and |error|)")
    table(rows, list(rows[0]))
    for case, d in cases.items():
        print(f"  {case}: reference {d['reference']['label']} K={d['reference']['K']:.7g}; check "
              f"{d['reference_check']['label']}: {100 * (d['reference_check']['signed_error'] or float('nan')):+.4f} %"
              + (f"; contacts add {100 * d['contact_share']:.1f} % to K" if "contact_share" in d else ""))
        print("    front: " + " -> ".join(f"{f['label']} ({f['run_s']:.3g} s, {100 * f['abs_error']:.3g} %)"
                                           for f in d["front"]))
    total = time.perf_counter() - t0
    print(f"total {total:.1f} s.")
    info = machine_info()
    out = {"benchmark": "pareto", "machine": info, "settings": vars(args), "total_time_s": total, "cases": cases,
           "rows": rows, "error_floor_in_plots": ERR_FLOOR}
    path = write_json(args.out, out)
    print(f"wrote {path}")
    stem = os.path.splitext(args.out)[0]
    note = f"{info['device']} ({info['cpu_count']} cores), jax {info['jax']}, float64, seed {args.seed}"
    for case, d in cases.items():
        print(f"wrote {plot(case, d, f'{stem}_{case}.png', note)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
