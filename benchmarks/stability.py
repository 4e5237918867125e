#!/usr/bin/env python
"""Where the methods fail: four stability and accuracy studies of the DEM, the DSM and the STE.

Usage::

    python benchmarks/stability.py --quick      # 400 particles, fewer points: about 1.5 min on 2 cores
    python benchmarks/stability.py              # 1200 particles: about 3 min on one core

One dense random box (bonds at contacts, Hertz-Mindlin contacts superimposed on the bonds, particle E = 1e10 Pa,
nu = 0.25, friction 0.5 unless varied), compressed between clamped layers. Each study prints a table, fills one
section of ``results/stability.json`` (``results/stability_quick.json`` with ``--quick``) and draws
``results/stability_<study>.png``:

1. ``ste_contact_share`` -- STE error against the share of the stiffness the contacts carry. The bond modulus E_b
   goes from 1e7 to 1e10 Pa with the particles fixed at 1e10 Pa. Reference: the DEM with contacts. Contact share
   = 1 - K_bonds_only / K_with_contacts, both from the DEM. Also the linear (bonds-only) DSM against the same
   reference, and the STE without contacts against the bonds-only DEM (the STE's own error).
2. ``dsm_strain`` -- the nonlinear DSM (Newton-Krylov, Hertz contacts) at strains 0.1 % to 5 %, with slip at the
   Coulomb limit (the default) and without slip (``slip=False``, Jarolin & Dosta's assumption): Newton iterations,
   converged flag, final relative residual and stiffness error against the DEM. Newton is capped
   (``--newton-maxiter`` per load step, ``--krylov-restarts`` GMRES restarts of 40 vectors) so no solve runs for
   minutes; a solve that misses the tolerance at the cap counts as not converged.
3. ``dsm_sliding`` -- the DEM's Coulomb limit lets contacts slide. The friction coefficient goes from 0.05 to 1
   (and 10, near no-slip); the sliding contacts are counted in the DEM's final state (|F_t| >= 0.99 mu F_n,
   recomputed from the stored tangential springs: the DEM state does not expose the count). The no-slip DSM lifts
   the Coulomb limit (one solve serves every friction coefficient); the DSM with slip is solved per coefficient.
4. ``dem_time_step`` -- the DEM time step as a multiple of the critical step estimate (power iteration on the bonds
   plus a contact term), bonds only and with contacts: stable (K within 1 % of the run at the default step),
   inaccurate (finishes, K off), the library's InstabilityError, or a neighbour-list re-allocation loop (see
   below); and the loading time in elastic-wave transits (the ``transits`` option; strain rate = strain / loading
   time) against the linear DSM's static answer on the bonds-only sample.

Every method call that raises is recorded in the results, not fatal. The output ends with conclusions computed from
the numbers (also under ``"conclusions"`` in the JSON).

An unstable DEM run raises ``InstabilityError`` (the DEM checks for runaway motion before it re-allocates a
neighbour list, and stops after 4 re-allocations of one chunk); a wall-clock alarm per DEM run guards the budget.

Measured run times (``time python benchmarks/stability.py [--quick]``, 2-core CPU shared with other work, float64,
jax 0.10.2): ``--quick`` (400 particles, 1114 bonds) 1 min 27 s; full (1199 particles, 3560 bonds) 2 min 53 s on one
core (`--threads 1`).
Most of it is compilation (DEM chunk with contacts, Newton-Krylov), once per sample size.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import time

from _common import enable_x64, machine_info, pin_threads, table, write_json

STUDIES = ("ste_contact_share", "dsm_strain", "dsm_sliding", "dem_time_step")
PARTICLE = {"E": 1e10, "nu": 0.25, "density": 2500.0, "friction": 0.5, "restitution": 0.5}
BOND_NU = 0.25


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def fmt_err(exc) -> str:
    return f"{type(exc).__name__}: {str(exc).splitlines()[0][:300]}"


# ------------------------------------------------------------------------------------------------------ guards
class RunTimeout(RuntimeError):
    """A DEM run exceeded the benchmark's wall-clock budget."""


@contextlib.contextmanager
def dem_guard(budget_s: float):
    """Stop a DEM run that runs past ``budget_s`` (``RunTimeout``, where the platform has ``SIGALRM``)."""

    def alarm(signum, frame):
        raise RunTimeout(f"DEM run exceeded the benchmark budget of {budget_s:.0f} s")

    use_alarm = hasattr(signal, "SIGALRM")
    if use_alarm:
        previous = signal.signal(signal.SIGALRM, alarm)
        signal.alarm(max(1, int(budget_s)))
    try:
        yield
    finally:
        if use_alarm:
            signal.alarm(0)
            signal.signal(signal.SIGALRM, previous)


# ------------------------------------------------------------------------------------------------------ runs
def params_for(E_b):
    import numpy as np

    return {"bond_E": np.array([float(E_b)]), "bond_nu": np.array([BOND_NU])}


def run_dem(sample, scene, params, budget_s, **opts):
    """A DEM run as a record: K, time step, steps, times; or the error that stopped it."""
    import jaxbpm

    t = time.perf_counter()
    try:
        with dem_guard(budget_s):
            r = jaxbpm.solve(sample, scene, "dem", params=params, **opts)
    except Exception as exc:  # recorded, not fatal
        return {"error": fmt_err(exc), "error_type": type(exc).__name__, "wall_s": time.perf_counter() - t}, None
    rec = {"K": float(r.stiffness), "dt": r.stats["dt"], "dt_crit": r.stats["dt_crit"], "steps": r.stats["steps"],
           "loading_time": r.stats["loading_time"], "run_s": float(r.run_time),
           "compile_s": float(r.compile_time) if r.compile_time == r.compile_time else None,
           "reallocations": r.stats.get("reallocations", 0), "wall_s": time.perf_counter() - t}
    return rec, r


def run_dsm(sample, scene, params, **opts):
    import jaxbpm

    t = time.perf_counter()
    try:
        r = jaxbpm.solve(sample, scene, "dsm", params=params, throw=False, **opts)  # the status is recorded
    except Exception as exc:  # recorded, not fatal
        return {"error": fmt_err(exc), "error_type": type(exc).__name__, "wall_s": time.perf_counter() - t}
    st = r.stats
    return {"K": float(r.stiffness), "converged": bool(st["converged"]), "iterations": int(st.get("iterations", 0)),
            "residual": float(st["residual"]), "residual_history": [float(v) for v in st.get("residual_history", [])],
            "run_s": float(r.run_time), "compile_s": float(r.compile_time), "wall_s": time.perf_counter() - t}


def run_call(fn):
    t = time.perf_counter()
    try:
        value = float(fn())
    except Exception as exc:  # recorded, not fatal
        return {"error": fmt_err(exc), "error_type": type(exc).__name__, "wall_s": time.perf_counter() - t}
    return {"K": value, "wall_s": time.perf_counter() - t}


def rel(a, b):
    """a / b - 1 for two records (None when either failed)."""
    if a is None or b is None or "K" not in a or "K" not in b or not b["K"]:
        return None
    return a["K"] / b["K"] - 1.0


def sliding_contacts(sample, result, threshold=0.99):
    """Active and sliding contacts of a DEM run's final state: |F_t| >= threshold x mu F_n.

    Recomputed from the state (positions, the neighbour-list pairs and the stored tangential springs) with the
    Hertz-Mindlin law of :mod:`jaxbpm.physics.contact`: F_n = 4/3 E* sqrt(R*) delta^1.5, F_t = 8 G* sqrt(R* delta)
    |xi_t| (a sliding contact's spring is stored shortened to the Coulomb limit, so its ratio is 1).
    """
    import numpy as np

    st = result.state
    n = sample.n_particles
    pos, rad = np.asarray(st.positions), np.asarray(sample.radii)
    pairs = np.asarray(st.nbrs.idx).T
    keep = pairs[:, 0] < n
    pairs, spring = pairs[keep], np.asarray(st.spring)[keep]
    d = pos[pairs[:, 1]] - pos[pairs[:, 0]]
    dist = np.linalg.norm(d, axis=1)
    nrm = d / dist[:, None]
    ri, rj = rad[pairs[:, 0]], rad[pairs[:, 1]]
    delta = ri + rj - dist
    active = delta > 0
    pm = sample.particle_material
    E, nu, mu = float(pm.E), float(pm.nu), float(pm.friction)
    e_star = E / (2.0 * (1.0 - nu**2))
    g_star = E / (2.0 * (1.0 + nu)) / (2.0 * (2.0 - nu))
    r_star = ri * rj / (ri + rj)
    dp = np.where(active, delta, 0.0)
    fn = 4.0 / 3.0 * e_star * np.sqrt(r_star) * dp**1.5
    xi_t = spring - np.sum(spring * nrm, axis=1)[:, None] * nrm
    ft = 8.0 * g_star * np.sqrt(r_star * dp) * np.linalg.norm(xi_t, axis=1)
    ratio = np.where(active & (fn > 0), ft / np.maximum(mu * fn, 1e-300), 0.0)
    sliding = active & (ratio >= threshold)
    return {"active": int(active.sum()), "sliding": int(sliding.sum()),
            "sliding_fraction": float(sliding.sum() / max(active.sum(), 1)),
            "sliding_normal_force_fraction": float(fn[sliding].sum() / max(fn.sum(), 1e-300))}


def crossing(xs, ys, level):
    """The first x (sorted ascending) at which |y| rises above ``level``, interpolated linearly; ``None`` if never,
    ``("below", x0)`` if already above at the first point."""
    pts = sorted((x, abs(y)) for x, y in zip(xs, ys) if x is not None and y is not None)
    if not pts:
        return None
    if pts[0][1] > level:
        return ("below", pts[0][0])
    for (x0, y0), (x1, y1) in zip(pts, pts[1:]):
        if y0 <= level < y1:
            return x0 + (level - y0) * (x1 - x0) / (y1 - y0)
    return None


def pct(v, digits=1):
    return "n/a" if v is None else f"{100 * v:+.{digits}f} %"


# ------------------------------------------------------------------------------------------------------ studies
def study_ste_contact_share(sample, args):
    import jax

    from jaxbpm import ste
    from jaxbpm.scenes import UniaxialCompression

    scene_c = UniaxialCompression(strain=args.strain, contacts=True)
    scene_b = UniaxialCompression(strain=args.strain, contacts=False)
    ste_c = ste_b = None
    rows = []
    for E_b in args.bond_E:
        p = params_for(E_b)
        log(f"  E_b = {E_b:.3g} Pa")
        dem_c, _ = run_dem(sample, scene_c, p, args.budget, chunk=args.chunk)
        dem_b, _ = run_dem(sample, scene_b, p, args.budget, chunk=args.chunk)
        dsm_b = run_dsm(sample, scene_b, p)
        dsm_lc = run_dsm(sample, scene_c, p, nonlinear=False)  # linear, contacts linearised (2 passes)
        if ste_c is None:
            try:
                ste_c = jax.jit(ste.stiffness_function(sample, scene_c))
            except Exception as exc:
                ste_c = exc
            try:
                ste_b = jax.jit(ste.stiffness_function(sample, scene_b))
            except Exception as exc:
                ste_b = exc
        rec_ste_c = run_call(lambda: ste_c(p)) if callable(ste_c) else {"error": fmt_err(ste_c)}
        rec_ste_b = run_call(lambda: ste_b(p)) if callable(ste_b) else {"error": fmt_err(ste_b)}
        share = None if rel(dem_b, dem_c) is None else -rel(dem_b, dem_c)
        row = {"bond_E": E_b, "contact_share": share, "K_dem_contacts": dem_c.get("K"),
               "K_dem_bonds": dem_b.get("K"), "ste_error": rel(rec_ste_c, dem_c),
               "dsm_linear_error": rel(dsm_b, dem_c), "ste_bonds_error": rel(rec_ste_b, dem_b),
               "dsm_linear_contacts_error": rel(dsm_lc, dem_c),
               "dsm_linear_vs_dem_bonds": rel(dsm_b, dem_b),
               "runs": {"dem_contacts": dem_c, "dem_bonds": dem_b, "dsm_linear": dsm_b,
                        "dsm_linear_contacts": dsm_lc, "ste_contacts": rec_ste_c,
                        "ste_bonds": rec_ste_b}}
        log(f"    share {pct(share)}, STE {pct(row['ste_error'])}, DSM linear {pct(row['dsm_linear_error'])}, "
            f"STE bonds-only vs DEM bonds-only {pct(row['ste_bonds_error'])}; DEM {dem_c.get('wall_s', 0):.1f} s"
            + "".join(f"; {k} FAILED {v['error']}" for k, v in row["runs"].items() if "error" in v))
        rows.append(row)
    print(f"\n[1] STE error vs contact share of the stiffness (strain {100 * args.strain:g} %, particle E "
          f"{PARTICLE['E']:.3g} Pa; reference: DEM with contacts; share from DEM with/without contacts)")
    table([{"E_b [Pa]": r["bond_E"], "contact share %": _p(r["contact_share"]),
            "K DEM [N/m]": r["K_dem_contacts"] if r["K_dem_contacts"] is not None else "FAILED",
            "STE err %": _p(r["ste_error"]), "DSM linear err %": _p(r["dsm_linear_error"]),
            "DSM lin+contacts err %": _p(r["dsm_linear_contacts_error"]),
            "STE bonds-only vs DEM bonds %": _p(r["ste_bonds_error"])} for r in rows],
          ["E_b [Pa]", "contact share %", "K DEM [N/m]", "STE err %", "DSM linear err %", "DSM lin+contacts err %",
           "STE bonds-only vs DEM bonds %"])
    shares = [r["contact_share"] for r in rows]
    conclusions = []
    for name, key in (("STE", "ste_error"), ("linear DSM", "dsm_linear_error"),
                      ("linear DSM with linearised contacts", "dsm_linear_contacts_error")):
        errs = [r[key] for r in rows]
        for level in (0.05, 0.10):
            x = crossing(shares, errs, level)
            if x is None:
                ok = [s for s, e in zip(shares, errs) if s is not None and e is not None]
                text = (f"{name} error stays within {100 * level:.0f} % over the measured contact shares "
                        f"({100 * min(ok):.1f}-{100 * max(ok):.1f} %)" if ok else f"{name}: no successful run")
            elif isinstance(x, tuple):
                text = (f"{name} error exceeds {100 * level:.0f} % already at the smallest measured contact share "
                        f"({100 * x[1]:.1f} %)")
            else:
                text = f"{name} error exceeds {100 * level:.0f} % once contacts carry more than {100 * x:.1f} % of " \
                       "the stiffness"
            conclusions.append(text)
    lin = [abs(r["dsm_linear_error"] + r["contact_share"]) for r in rows
           if r["dsm_linear_error"] is not None and r["contact_share"] is not None]
    if lin:
        conclusions.append(f"the linear DSM ignores the contacts: its error is minus the contact share to within "
                           f"{100 * max(lin):.2f} points (its own error against the bonds-only DEM)")
    ok = [r for r in rows if r["ste_error"] is not None and r["contact_share"] is not None]
    if ok:
        worst = max(ok, key=lambda r: abs(r["ste_error"]))
        conclusions.append(f"STE worst error {pct(worst['ste_error'])} at contact share "
                           f"{100 * worst['contact_share']:.1f} % (E_b = {worst['bond_E']:.3g} Pa); without contacts "
                           f"the STE is within {100 * max(abs(r['ste_bonds_error'] or 0) for r in ok):.1f} % of the "
                           "bonds-only DEM at every E_b")
    return {"reference": "DEM with contacts (the DEM was fast enough)", "strain": args.strain,
            "particle_E": PARTICLE["E"], "rows": rows, "conclusions": conclusions}


def _p(v):
    return float("nan") if v is None else 100.0 * v


def study_dsm_strain(sample, args, cache):
    from jaxbpm.scenes import UniaxialCompression

    p = params_for(args.mid_E)
    opts = dict(newton_maxiter=args.newton_maxiter, maxiter=args.krylov_restarts, load_steps=args.load_steps)
    rows = []
    for strain in args.strains:
        scene = UniaxialCompression(strain=strain, contacts=True)
        log(f"  strain {100 * strain:g} %")
        dem, _ = run_dem(sample, scene, p, args.budget, chunk=args.chunk)
        dsm = run_dsm(sample, scene, p, **opts)
        dsm_ns = run_dsm(sample, scene, p, slip=False, **opts)
        cache[("dsm", strain)] = dsm
        cache[("dsm_noslip", strain)] = dsm_ns
        cache[("dem", strain)] = dem
        dem_b, _ = run_dem(sample, UniaxialCompression(strain=strain), p, args.budget, chunk=args.chunk)
        row = {"strain": strain, "K_dem": dem.get("K"), "K_dsm": dsm.get("K"), "converged": dsm.get("converged"),
               "iterations": dsm.get("iterations"), "residual": dsm.get("residual"), "error": rel(dsm, dem),
               "contact_share": None if rel(dem_b, dem) is None else -rel(dem_b, dem),
               "dsm_run_s": dsm.get("run_s"), "K_dsm_noslip": dsm_ns.get("K"),
               "error_noslip": rel(dsm_ns, dem), "converged_noslip": dsm_ns.get("converged"),
               "residual_noslip": dsm_ns.get("residual"), "dsm_noslip_run_s": dsm_ns.get("run_s"),
               "runs": {"dem": dem, "dsm": dsm, "dsm_noslip": dsm_ns, "dem_bonds": dem_b}}
        log(f"    no-slip DSM {pct(row['error_noslip'])} vs DEM, converged {row['converged_noslip']}")
        log(f"    DSM {pct(row['error'])} vs DEM, converged {row['converged']}, {row['iterations']} iterations, "
            f"residual {row['residual']}, {dsm.get('wall_s', 0):.1f} s"
            + "".join(f"; {k} FAILED {v['error']}" for k, v in row["runs"].items() if "error" in v))
        rows.append(row)
    print(f"\n[2] Nonlinear DSM (Hertz contacts sliding at the Coulomb limit, the default; and without slip) vs "
          f"strain (E_b = {args.mid_E:.3g} Pa, at most "
          f"{args.newton_maxiter} Newton iterations per load step x {args.load_steps} steps, "
          f"{args.krylov_restarts} GMRES restarts; converged: every load step reached the 1e-3 tolerance; residual: "
          "at the last load step)")
    table([{"strain %": 100 * r["strain"], "contact share %": _p(r["contact_share"]),
            "converged": r["converged"] if r["K_dsm"] is not None else "FAILED", "Newton its": r["iterations"],
            "residual": r["residual"] if r["residual"] is not None else float("nan"), "DSM err %": _p(r["error"]),
            "DSM run s": r["dsm_run_s"] if r["dsm_run_s"] is not None else float("nan"),
            "no-slip err %": _p(r["error_noslip"]), "no-slip conv.": r["converged_noslip"],
            "no-slip run s": r["dsm_noslip_run_s"] if r["dsm_noslip_run_s"] is not None else float("nan")}
           for r in rows],
          ["strain %", "contact share %", "converged", "Newton its", "residual", "DSM err %", "DSM run s",
           "no-slip err %", "no-slip conv.", "no-slip run s"])
    conv = [r for r in rows if r["converged"]]
    fail = [r for r in rows if not r["converged"]]
    conclusions = []
    if conv:
        conclusions.append(f"nonlinear DSM converges (within the cap) up to {100 * max(r['strain'] for r in conv):g} "
                           f"% strain; its error against the DEM there is "
                           + ", ".join(f"{pct(r['error'])} at {100 * r['strain']:g} %" for r in conv))
    if fail:
        first = min(r["strain"] for r in fail)
        conclusions.append(f"it misses the 1e-3 residual in some load step from {100 * first:g} % strain on (last "
                           f"step's residual "
                           f"{', '.join(format(r['residual'] or float('nan'), '.2g') for r in fail)} at "
                           f"{', '.join(format(100 * r['strain'], 'g') for r in fail)} %), with errors "
                           f"{', '.join(pct(r['error']) for r in fail)}")
    errs = [(r["strain"], r["error"]) for r in rows if r["error"] is not None]
    if len(errs) > 1:
        conclusions.append(f"the DSM's stiffness error grows with strain from {pct(errs[0][1])} "
                           f"({100 * errs[0][0]:g} %) to {pct(errs[-1][1])} ({100 * errs[-1][0]:g} %)"
                           if abs(errs[-1][1]) > abs(errs[0][1]) else
                           f"the DSM's stiffness error does not grow with strain ({pct(errs[0][1])} at "
                           f"{100 * errs[0][0]:g} %, {pct(errs[-1][1])} at {100 * errs[-1][0]:g} %)")
    ns = [(r["strain"], r["error_noslip"]) for r in rows if r["error_noslip"] is not None]
    if ns:
        conclusions.append("without slip (Jarolin & Dosta's assumption) the error is "
                           + ", ".join(f"{pct(e)} at {100 * x:g} %" for x, e in ns)
                           + f"; {sum(bool(r['converged_noslip']) for r in rows)} of {len(rows)} such solves converge")
    return {"reference": "DEM with contacts", "bond_E": args.mid_E,
            "dsm_options": {**opts, "tol": 1e-3}, "rows": rows, "conclusions": conclusions}


def study_dsm_sliding(sample, args, cache):
    from jaxbpm.scenes import UniaxialCompression

    p = params_for(args.mid_E)
    scene = UniaxialCompression(strain=args.strain, contacts=True)
    opts = dict(newton_maxiter=args.newton_maxiter, maxiter=args.krylov_restarts, load_steps=args.load_steps)
    dsm = cache.get(("dsm_noslip", args.strain))
    if dsm is None:
        log("  no-slip DSM (friction plays no part: it lifts the Coulomb limit)")
        dsm = run_dsm(sample, scene, p, slip=False, **opts)
    rows = []
    for mu in args.frictions:
        s_mu = sample.replace(particle_material={**PARTICLE, "friction": mu})
        dem, res = run_dem(s_mu, scene, p, args.budget, chunk=args.chunk)
        slide = sliding_contacts(s_mu, res) if res is not None else {}
        slip = cache.get(("dsm", args.strain)) if mu == PARTICLE["friction"] else None
        slip = run_dsm(s_mu, scene, p, **opts) if slip is None else slip
        row = {"friction": mu, "K_dem": dem.get("K"), "K_dsm": dsm.get("K"), "dsm_converged": dsm.get("converged"),
               "error": rel(dsm, dem), "K_dsm_slip": slip.get("K"), "error_slip": rel(slip, dem),
               "slip_converged": slip.get("converged"), **slide, "runs": {"dem": dem, "dsm_slip": slip}}
        log(f"  mu = {mu:g}: {slide.get('sliding')} of {slide.get('active')} contacts sliding, no-slip DSM "
            f"{pct(row['error'])}, DSM with slip {pct(row['error_slip'])} vs DEM"
            + (f"; DEM FAILED {dem['error']}" if "error" in dem else ""))
        rows.append(row)
    print(f"\n[3] Nonlinear DSM, no slip and with slip, vs sliding contacts in the DEM (strain "
          f"{100 * args.strain:g} %, E_b = {args.mid_E:.3g} Pa; no-slip DSM converged: {dsm.get('converged')}, "
          f"K = {dsm.get('K', float('nan')):.4g} N/m)")
    table([{"friction": r["friction"], "active contacts": r.get("active", ""), "sliding": r.get("sliding", ""),
            "sliding %": _p(r.get("sliding_fraction")),
            "F_n on sliding %": _p(r.get("sliding_normal_force_fraction")),
            "K DEM [N/m]": r["K_dem"] if r["K_dem"] is not None else "FAILED", "no-slip DSM err %": _p(r["error"]),
            "DSM (slip) err %": _p(r["error_slip"]), "slip conv.": r["slip_converged"]}
           for r in rows],
          ["friction", "active contacts", "sliding", "sliding %", "F_n on sliding %", "K DEM [N/m]",
           "no-slip DSM err %", "DSM (slip) err %", "slip conv."])
    ok = [r for r in rows if r["error"] is not None and "sliding_fraction" in r]
    conclusions = []
    if ok:
        import numpy as np

        most = max(ok, key=lambda r: r["sliding_fraction"])
        least = min(ok, key=lambda r: r["sliding_fraction"])
        conclusions.append(
            f"in the DEM {100 * most['sliding_fraction']:.0f} % of the contacts slide at mu = {most['friction']:g} "
            f"and {100 * least['sliding_fraction']:.0f} % at mu = {least['friction']:g}; the no-slip DSM's error "
            f"goes from {pct(most['error'])} to {pct(least['error'])}")
        if len(ok) > 2:
            x = np.array([r["sliding_fraction"] for r in ok])
            y = np.array([r["error"] for r in ok])
            if np.ptp(x) > 0 and np.ptp(y) > 0:
                slope = np.polyfit(x, y, 1)[0]
                conclusions.append(f"correlation of the DSM error with the sliding fraction: r = "
                                   f"{np.corrcoef(x, y)[0, 1]:.2f} ({100 * slope / 10:+.1f} % error per 10 % more "
                                   "contacts sliding)")
        if not dsm.get("converged"):
            conclusions.append(f"(the no-slip DSM solve at this strain stopped at residual "
                               f"{dsm.get('residual', float('nan')):.2g}, above the 1e-3 tolerance; its agreement "
                               f"with the DEM at mu = {least['friction']:g} ({pct(least['error'])}) shows the "
                               "stiffness is nevertheless close)")
        es = [r["error_slip"] for r in ok if r["error_slip"] is not None]
        if es:
            conclusions.append(f"the DSM with slip (the default) is within {pct(min(es, key=abs))} to "
                               f"{pct(max(es, key=abs))} of the DEM over mu = {ok[0]['friction']:g} to "
                               f"{ok[-1]['friction']:g} ({sum(bool(r['slip_converged']) for r in ok)} of {len(ok)} "
                               "solves converged to the 1e-3 residual)")
        if abs(least["error"]) > 0.05:
            conclusions.append(f"even with few sliding contacts (mu = {least['friction']:g}) the DSM is "
                               f"{pct(least['error'])} off: slip explains only part of its error at this strain")
    return {"reference": "DEM with contacts", "bond_E": args.mid_E, "strain": args.strain,
            "dsm": dsm, "sliding_test": "|F_t| >= 0.99 mu F_n in the DEM's final state", "rows": rows,
            "conclusions": conclusions}


def study_dem_time_step(sample, args):
    from jaxbpm.scenes import UniaxialCompression

    p = params_for(args.mid_E)
    variants = (("bonds only", False, args.dt_factors_bonds), ("bonds + contacts", True, args.dt_factors_contacts))
    dt_rows = []
    for label, contacts, factors in variants:
        scene = UniaxialCompression(strain=args.strain, contacts=contacts)
        base, _ = run_dem(sample, scene, p, args.budget, chunk=args.chunk)  # safety 0.5: the default step
        if "K" not in base:
            dt_rows.append({"variant": label, "factor": 0.5, "outcome": base["error_type"], "error": None,
                            "run": base})
            continue
        dt_crit = base["dt_crit"]
        for f in factors:
            rec = base if f == 0.5 else run_dem(sample, scene, p, args.budget, chunk=args.chunk, dt=f * dt_crit)[0]
            err = rel(rec, base)
            if "K" in rec:
                outcome = "stable" if abs(err) <= 0.01 else "inaccurate"
            else:
                outcome = {"RunTimeout": "timeout"}.get(rec["error_type"], rec["error_type"])
            row = {"variant": label, "factor": f, "dt": f * dt_crit, "dt_crit": dt_crit, "outcome": outcome,
                   "error": err, "steps": rec.get("steps"), "wall_s": rec["wall_s"], "run": rec}
            log(f"  {label}: dt = {f:g} x dt_crit: {outcome} {pct(err, 2)}"
                + (f" ({rec['error']})" if "error" in rec else ""))
            dt_rows.append(row)
    print(f"\n[4a] DEM time step as a multiple of the critical step estimate (strain {100 * args.strain:g} %, "
          f"E_b = {args.mid_E:.3g} Pa; K against the run at the default 0.5 x dt_crit)")
    table([{"variant": r["variant"], "dt / dt_crit": r["factor"], "outcome": r["outcome"],
            "K err %": _p(r["error"]), "steps": r.get("steps") or "", "wall s": r.get("wall_s", float("nan"))}
           for r in dt_rows], ["variant", "dt / dt_crit", "outcome", "K err %", "steps", "wall s"])

    # a small strain, so that the bonds' geometric nonlinearity (of the order of the strain) does not hide the
    # dynamic error; a short chunk, since a run is rounded up to whole chunks (past the target strain)
    scene_b = UniaxialCompression(strain=args.rate_strain)
    length = scene_b.geometry(sample)[0]
    static = run_dsm(sample, scene_b, p)
    rate_rows = []
    for tr in args.transits:
        rec, res = run_dem(sample, scene_b, p, args.budget, chunk=args.rate_chunk, transits=tr)
        err = rel(rec, static)
        speed = res.stats["speed"] if res is not None else None
        row = {"transits": tr, "strain_rate": speed / length if speed else None,
               "loading_time": args.rate_strain * length / speed if speed else None,
               "steps": round(args.rate_strain * length / speed / rec["dt"]) if speed else None,
               "error": err, "run": rec}
        log(f"  transits {tr:g}: {pct(err, 3)} vs the static DSM" + (f" ({rec['error']})" if "error" in rec else ""))
        rate_rows.append(row)
    print(f"\n[4b] DEM loading rate vs the quasi-static answer (bonds only, strain {100 * args.rate_strain:g} %, "
          f"linear DSM K = {static.get('K', float('nan')):.6g} N/m; loading time to the target strain = transits x "
          "elastic-wave crossing time)")
    table([{"transits": r["transits"], "loading time [s]": r["loading_time"] or float("nan"),
            "strain rate [1/s]": r["strain_rate"] or float("nan"), "steps": r["steps"] or "",
            "K err %": _p(r["error"])} for r in rate_rows],
          ["transits", "loading time [s]", "strain rate [1/s]", "steps", "K err %"])

    conclusions = []
    for label, _, _ in variants:
        rs = sorted((r for r in dt_rows if r["variant"] == label), key=lambda r: r["factor"])
        stable = [r["factor"] for r in rs if r["outcome"] == "stable"]
        bad = [r for r in rs if r["outcome"] != "stable"]
        first_bad = min(bad, key=lambda r: r["factor"]) if bad else None
        text = f"DEM {label}: K within 1 % up to {max(stable):g} x the critical step estimate" if stable else \
            f"DEM {label}: no stable run"
        if first_bad is not None:
            text += (f"; first failure at {first_bad['factor']:g} x ({first_bad['outcome']}"
                     + (f", K {pct(first_bad['error'])}" if first_bad["error"] is not None else "") + ")")
            kinds = sorted({r["outcome"] for r in bad})
            text += f"; outcomes above: {', '.join(kinds)}"
        else:
            text += " (no failure in the measured range)"
        conclusions.append(text)
    for level in (0.01, 0.001):
        ok = [r["transits"] for r in rate_rows if r["error"] is not None and abs(r["error"]) <= level]
        # the smallest transit count from which on every slower loading stays within the level
        good = None
        for r in sorted(rate_rows, key=lambda r: r["transits"], reverse=True):
            if r["error"] is not None and abs(r["error"]) <= level:
                good = r
            else:
                break
        if good is not None:
            conclusions.append(f"DEM K is within {100 * level:g} % of the static answer from {good['transits']:g} "
                               f"transits on (strain rate {good['strain_rate']:.3g} /s; the default is 40)")
        elif not ok:
            conclusions.append(f"no measured loading rate brings the DEM within {100 * level:g} % of the static answer")
    fastest = min(rate_rows, key=lambda r: r["transits"])
    if fastest["error"] is not None:
        conclusions.append(f"at {fastest['transits']:g} transits the DEM is {pct(fastest['error'], 2)} off")
    return {"reference": "time step: the DEM at the default step (0.5 x dt_crit); loading rate: the linear DSM",
            "bond_E": args.mid_E, "strain": args.strain, "rate_strain": args.rate_strain, "time_step": dt_rows,
            "static": static,
            "loading_rate": rate_rows, "conclusions": conclusions}


# ------------------------------------------------------------------------------------------------------ plots
def _save(fig, path):
    import matplotlib.pyplot as plt

    from jaxbpm.io import atomic_write

    fig.tight_layout(rect=(0, 0.03, 1, 1))
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=120, format="png"))
    plt.close(fig)
    return path


def plot_study(name, data, path, note):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    def arr(rows, key, scale=1.0):
        return np.array([np.nan if r.get(key) is None else scale * r[key] for r in rows], float)

    if name == "ste_contact_share":
        rows = data["rows"]
        fig, ax = plt.subplots(figsize=(7.5, 5))
        x = arr(rows, "contact_share", 100)
        for key, label, style in (("ste_error", "STE (linearised contacts)", "o-"),
                                  ("dsm_linear_error", "DSM linear (bonds only)", "s-"),
                                  ("dsm_linear_contacts_error", "DSM linear, contacts linearised", "D-"),
                                  ("ste_bonds_error", "STE bonds only vs DEM bonds only", "^--")):
            ax.plot(x, arr(rows, key, 100), style, label=label)
        for xi, yi, r in zip(x, arr(rows, "ste_error", 100), rows):
            if np.isfinite(xi) and np.isfinite(yi):
                ax.annotate(f"E_b={r['bond_E']:.0e}", (xi, yi), xytext=(4, -10), textcoords="offset points",
                            fontsize=7, alpha=0.8)
        ax.axhspan(-10, 10, color="0.9", zorder=0, label="+-10 %")
        ax.set_yscale("symlog", linthresh=10)
        ax.set_xlabel("contact share of the stiffness, 1 - K_bonds / K_contacts (DEM) [%]")
        ax.set_ylabel("stiffness error vs DEM with contacts [%]")
        ax.set_title("STE error vs share of contact stiffness")
        ax.legend(fontsize=8)
    elif name == "dsm_strain":
        rows = data["rows"]
        fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5))
        x = arr(rows, "strain", 100)
        for key, ckey, color, label in (("error", "converged", "C0", "with slip (default)"),
                                        ("error_noslip", "converged_noslip", "C1", "no slip")):
            err = arr(rows, key, 100)
            conv = np.array([bool(r[ckey]) for r in rows])
            ax.plot(x, err, "-", color=color)
            ax.plot(x[conv], err[conv], "o", color=color, label=f"{label}, converged")
            ax.plot(x[~conv], err[~conv], "o", mfc="none", color=color, label=f"{label}, not converged")
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.set_xscale("log")
        ax.set_xlabel("strain [%]")
        ax.set_ylabel("DSM stiffness error vs DEM [%]")
        ax.legend(fontsize=8)
        ax.set_title("nonlinear DSM error")
        bx.semilogx(x, arr(rows, "iterations"), "s-", color="C1", label="Newton iterations")
        bx.set_xlabel("strain [%]")
        bx.set_ylabel("Newton iterations (all load steps)")
        b2 = bx.twinx()
        b2.loglog(x, arr(rows, "residual"), "o--", color="C2", label="final residual")
        b2.axhline(1e-3, color="C2", lw=0.7, ls=":")
        b2.set_ylabel("relative residual (tolerance 1e-3 dotted)")
        h1, l1 = bx.get_legend_handles_labels()
        h2, l2 = b2.get_legend_handles_labels()
        bx.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper left")
        bx.set_title("convergence")
    elif name == "dsm_sliding":
        rows = data["rows"]
        fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5))
        mu = arr(rows, "friction")
        ax.semilogx(mu, arr(rows, "sliding_fraction", 100), "o-", label="contacts sliding")
        ax.semilogx(mu, arr(rows, "sliding_normal_force_fraction", 100), "s--", label="normal force on sliding")
        ax.set_xlabel("friction coefficient mu")
        ax.set_ylabel("share in the DEM's final state [%]")
        ax.legend(fontsize=8)
        ax.set_title("sliding contacts (|F_t| >= 0.99 mu F_n)")
        bx.plot(arr(rows, "sliding_fraction", 100), arr(rows, "error", 100), "o-", color="C1", label="no slip")
        bx.plot(arr(rows, "sliding_fraction", 100), arr(rows, "error_slip", 100), "s-", color="C0",
                label="with slip (default)")
        bx.axhline(0.0, color="0.5", lw=0.6)
        bx.legend(fontsize=8)
        for r in rows:
            if r.get("sliding_fraction") is not None and r["error"] is not None:
                bx.annotate(f"mu={r['friction']:g}", (100 * r["sliding_fraction"], 100 * r["error"]), fontsize=7)
        bx.set_xlabel("contacts sliding in the DEM [%]")
        bx.set_ylabel("DSM stiffness error vs DEM [%]")
        bx.set_title("DSM error vs sliding")
    else:
        fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5))
        marks = {"stable": "o", "inaccurate": "D", "InstabilityError": "x", "timeout": "*"}
        for k, variant in enumerate(("bonds only", "bonds + contacts")):
            rs = [r for r in data["time_step"] if r["variant"] == variant]
            if not rs:
                continue
            ax.plot([r["factor"] for r in rs if r["error"] is not None],
                    [100 * r["error"] for r in rs if r["error"] is not None], "-", color=f"C{k}", label=variant)
            top = 2.0 + 2.0 * k  # stopped runs have no K: drawn above the curves
            last = None
            for r in rs:
                y = 100 * r["error"] if r["error"] is not None else top
                ax.plot(r["factor"], y, marks.get(r["outcome"], "s"), color=f"C{k}", ms=8,
                        mfc="none" if r["outcome"] != "stable" else f"C{k}")
                if r["outcome"] != "stable" and (r["outcome"] != last or r["error"] is not None):
                    ax.annotate(r["outcome"], (r["factor"], y), xytext=(3, 3), textcoords="offset points",
                                fontsize=6, color=f"C{k}")
                last = r["outcome"]
        ax.axvline(1.0, color="k", lw=0.6, ls=":")
        ax.set_xlabel("time step / critical step estimate")
        ax.set_ylabel("K error vs default step [%] (stopped runs above 0)")
        ax.set_title("DEM time step (x, X: stopped runs)")
        ax.legend(fontsize=8)
        rr = [r for r in data["loading_rate"] if r["error"] is not None]
        bx.loglog([r["transits"] for r in rr], [max(abs(100 * r["error"]), 1e-6) for r in rr], "o-")
        bx.axhline(1.0, color="C3", lw=0.6, ls=":")
        bx.axhline(0.1, color="C2", lw=0.6, ls=":")
        bx.set_xlabel("loading time to the target strain [elastic-wave transits]")
        bx.set_ylabel("|K error| vs static linear DSM [%]")
        bx.set_title("DEM loading rate (bonds only)")
    fig.text(0.01, 0.005, note, fontsize=6.5, alpha=0.8)
    return _save(fig, path)


# ------------------------------------------------------------------------------------------------------ main
def build_sample(n, seed):
    import jaxbpm

    s = jaxbpm.generate.box(n, seed=seed, materials={"E": 1e9, "nu": BOND_NU}, particle_material=PARTICLE)
    return s.largest_cluster()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=1200, help="particles of the random box")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--strain", type=float, default=0.005, help="strain of studies 1, 3 and 4")
    ap.add_argument("--mid-E", type=float, default=1e9, help="bond modulus [Pa] of studies 2-4")
    ap.add_argument("--newton-maxiter", type=int, default=8, help="Newton iterations per DSM load step")
    ap.add_argument("--krylov-restarts", type=int, default=3, help="GMRES restarts per Newton step (DSM maxiter)")
    ap.add_argument("--load-steps", type=int, default=4)
    ap.add_argument("--chunk", type=int, default=200, help="DEM steps per jitted chunk (fixed: one compilation)")
    ap.add_argument("--rate-strain", type=float, default=1e-4, help="strain of the loading-rate runs (study 4)")
    ap.add_argument("--rate-chunk", type=int, default=25, help="DEM chunk of the loading-rate runs")
    ap.add_argument("--budget", type=float, default=600.0, help="wall-clock limit of one DEM run [s]")
    ap.add_argument("--studies", nargs="+", default=list(STUDIES), choices=STUDIES)
    ap.add_argument("--threads", type=int, default=None, help="restrict to this many cores")
    ap.add_argument("--quick", action="store_true", help="400 particles and fewer points per study")
    ap.add_argument("--out", default="results/stability.json")
    args = ap.parse_args(argv)
    pin_threads(args.threads)
    if args.quick:
        args.n = min(args.n, 400)
        args.budget = min(args.budget, 180.0)
        args.bond_E = [1e7, 1e8, 1e9, 1e10, 1e11]
        args.strains = [0.001, 0.005, 0.02, 0.05]
        args.frictions = [0.05, 0.2, 0.5, 1.0, 10.0]
        args.dt_factors_bonds = [0.5, 1.0, 1.05, 1.2, 2.0]
        args.dt_factors_contacts = [0.5, 1.0, 1.25, 1.5, 2.0]
        args.transits = [1, 3, 10, 40, 160]
        if args.out == "results/stability.json":
            args.out = "results/stability_quick.json"
    else:
        args.bond_E = [1e7, 3e7, 1e8, 3e8, 1e9, 3e9, 1e10, 3e10, 1e11]
        args.strains = [0.001, 0.002, 0.005, 0.01, 0.02, 0.05]
        args.frictions = [0.05, 0.1, 0.2, 0.3, 0.5, 0.75, 1.0, 10.0]
        args.dt_factors_bonds = [0.25, 0.5, 0.9, 1.0, 1.02, 1.05, 1.1, 1.2, 1.5, 2.0]
        args.dt_factors_contacts = [0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0, 3.0]
        args.transits = [1, 2, 3, 5, 10, 20, 40, 80, 160, 320]
    if args.strain not in args.strains:
        args.strains = sorted(args.strains + [args.strain])
    enable_x64()

    t0 = time.perf_counter()
    log(f"generating a {args.n}-particle random box (seed {args.seed})")
    sample = build_sample(args.n, args.seed)
    info = machine_info()
    out = {"benchmark": "stability", "machine": info, "settings": vars(args),
           "sample": {"particles": sample.n_particles, "bonds": sample.n_bonds, "particle_material": PARTICLE,
                      "bond_nu": BOND_NU, "mean_coordination": 2.0 * sample.n_bonds / sample.n_particles,
                      "generate_s": time.perf_counter() - t0},
           "studies": {}, "conclusions": {}}
    log(f"  {sample.n_particles} particles, {sample.n_bonds} bonds ({out['sample']['generate_s']:.1f} s)")
    note = (f"{info['device']} ({info['cpu_count']} cores), jax {info['jax']}, {sample.n_particles} particles, "
            f"{sample.n_bonds} bonds, particle E {PARTICLE['E']:.0e} Pa")
    cache = {}
    pngs = []
    for name in STUDIES:
        if name not in args.studies:
            continue
        log(f"== {name}")
        ts = time.perf_counter()
        if name == "ste_contact_share":
            data = study_ste_contact_share(sample, args)
        elif name == "dsm_strain":
            data = study_dsm_strain(sample, args, cache)
        elif name == "dsm_sliding":
            data = study_dsm_sliding(sample, args, cache)
        else:
            data = study_dem_time_step(sample, args)
        data["wall_s"] = time.perf_counter() - ts
        log(f"   {name}: {data['wall_s']:.1f} s")
        out["studies"][name] = data
        out["conclusions"][name] = data["conclusions"]
        png = f"{os.path.splitext(args.out)[0]}_{name}.png"  # results/stability_<study>.png (_quick_ with --quick)
        try:
            pngs.append(plot_study(name, data, png, note))
        except Exception as exc:  # a plot problem must not lose the numbers
            log(f"   plot FAILED: {fmt_err(exc)}")
        out["total_time_s"] = time.perf_counter() - t0
        write_json(args.out, out)  # after every study: a crash keeps what was measured
    print("\nConclusions:")
    for name, lines in out["conclusions"].items():
        for line in lines:
            print(f"  [{name}] {line}")
    print(f"\ntotal {out['total_time_s']:.0f} s")
    print(f"wrote {args.out}")
    for p in pngs:
        print(f"wrote {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
