#!/usr/bin/env python
"""DSM vs DEM (and a sparse direct solve): the stiffness of a bonded sample in uniaxial compression, three ways.

Usage::

    python benchmarks/dsm_vs_dem.py                       # sizes 2k 3k 10k 50k, ~15-20 min on one core
    python benchmarks/dsm_vs_dem.py --quick               # smoke run (small samples, ~3 min)
    python benchmarks/dsm_vs_dem.py --sizes 2000 10000 --no-contacts --dem-max 10000

What is compared (the SAME sample for every method of one size)
----------------------------------------------------------------
* Sample: ``jaxbpm.generate.box(n, seed).largest_cluster()`` (random polydisperse packing, bonds at contacts).
* Scene: ``UniaxialCompression(strain=0.002, boundary="layers")``: bottom layer clamped, top layer moved rigidly.
* DEM (bonds only, 6 DOF, the reference): ``jaxbpm.solve(..., "dem")`` with its defaults (local damping 0.7,
  loading over 40 elastic-wave transit times, time step 0.5 x critical); compile and run time as the DEM reports
  them (run = median chunk time x chunks), run once. Skipped above ``--dem-max`` particles (said in the output).
  Optionally a rotation-free DEM (3 DOF, ``--dem3-max``): the matched reference of the 3-DOF DSM, which is a
  different (stiffer) model than the 6-DOF one.
* DSM linear (bonds only): ``jaxbpm.solve(..., "dsm", ...)`` -- preconditioned CG on the element-by-element
  stiffness operator (per-bond Jacobians of the same bond law), stiffness from the strain energy. Configurations:
  6 DOF (the library's default: two-level preconditioner, relative residual 1e-6), 6 DOF with ``stiffness_tol``
  (stop when the energy has settled to 1e-3, ``--stiffness-tol``), 6 DOF with block-Jacobi alone, 3 DOF (default
  preconditioner). Each is called ``--repeats`` times: the first call's compile time, the min / median run time
  (jitted solve only, ``block_until_ready``) and wall time (whole ``solve`` call) of the calls, CG iterations.
* Sparse direct solve of the SAME linear 6-DOF system (``--splu-max``): the global stiffness assembled from
  ``dsm.bond_jacobians`` (``jax.jacfwd`` of the same bond law; ``coo_matrix -> csc``), restricted to the free
  DOFs, ``scipy.sparse.linalg.splu(K_ff)`` (SuperLU, COLAMD ordering) and ``K_ff u_f = -K_fp u_p``; reaction and
  stiffness exactly as the DSM measures them. Timed: Jacobians (jitted, compiled beforehand), assembly
  (COO -> CSC, restriction), factorisation, solve; ``--repeats`` times (min / median). The assembled matrix is
  checked against the DSM operator (``K v`` vs the jvp on a random ``v``), the stiffness against the DSM-6 one.
* Nonlinear DSM with Hertz contacts (``contacts=True``: Newton-Krylov over 4 load steps, contact candidates fixed
  at rest, sliding at the Coulomb limit: the library's defaults) vs DEM with contacts (Hertz-Mindlin, neighbour
  list) at ``--contact-sizes``. The nonlinear DSM is one compiled program (load steps in ``lax.scan``, Newton in
  ``lax.while_loop``): the first call compiles it, the repeats compile nothing; run time excludes compilation.

Speed-ups are run time to run time (compilation excluded on both sides) and wall to wall (each method's whole
``solve`` call, compilation and setup included, first call). The DSM's ``setup_s`` (once per sample, outside its run
time: the bond Jacobians and preconditioner parts per unit modulus, ``dsm.BondGeometry``) is reported beside it: a
calibration pays it once, every solve after that pays the run time. splu: "total" = Jacobians + assembly + factorisation +
solve (the Jacobians' compilation excluded), "f+s" = factorisation + solve only.
Timing: one core (the least busy one, unless ``--cpu``), XLA single-threaded; the load of every core is measured
before and after and written to the output -- the machine may be shared.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

from _common import cached_box, enable_x64, machine_info, machine_load, pin, table, write_json

DEFAULT_SIZES = [2000, 3000, 10000, 50000]
QUICK_SIZES = [500, 1000]


def spread(times) -> dict:
    import numpy as np

    t = np.asarray(times, float)
    return {"min": float(t.min()), "median": float(np.median(t)), "all": [float(x) for x in t]}


def log(msg):
    print(msg, file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------------------- linear system
class LinearSystem:
    """The linear DSM system of ``scene`` on ``sample`` with ``dofs`` per particle, built as ``dsm.solve_scene``
    builds it (same Model, free mask and prescribed displacements)."""

    def __init__(self, sample, scene, params, dofs):
        import jax.numpy as jnp
        import numpy as np

        from jaxbpm import dsm

        self.model = scene.model(sample, rotations=dofs == 6, contacts=False)
        self.params = params
        free, fixed, driven = dsm.free_mask(self.model, scene, sample)
        self.free_np, self.fixed, self.driven = free, fixed, driven
        length, _ = scene.geometry(sample)
        self.delta = scene.strain * length
        self.axis = scene.axis
        u_p = np.zeros(free.shape)
        u_p[driven, scene.axis] = -self.delta
        self.u_p_np = u_p
        self.free = jnp.asarray(free)
        self.u_p = jnp.asarray(u_p, self.model.positions0.dtype)
        self.nd = free.shape[1]

    def reaction(self, gen):
        """Reaction [N] from generalised internal forces ``gen [n, nd]`` (numpy or jax), as ``dsm.linear.linear_jit``."""
        comp = gen[:, self.axis]
        return 0.5 * (comp[self.driven].sum() - comp[self.fixed].sum())


def splu_solve(system: LinearSystem, repeats: int, budget: float = float("inf"), dsm_matvec_check=True) -> dict:
    """The same linear system assembled from dsm.bond_jacobians and solved by SuperLU; repeated ``repeats`` times,
    or fewer once the repeats so far took more than ``budget`` seconds (at least once)."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from jaxbpm import dsm

    model, params, nd = system.model, system.params, system.nd
    jac_fn = jax.jit(dsm.bond_jacobians)
    tc = time.perf_counter()
    jax.block_until_ready(jac_fn(model, params))
    jac_first = time.perf_counter() - tc
    bonds = np.asarray(model.bonds)
    ndof = model.n * nd
    free = system.free_np.ravel()
    fi, pi = np.flatnonzero(free), np.flatnonzero(~free)
    u_p = system.u_p_np.ravel()
    res = {"jacobians": [], "assembly": [], "factor": [], "solve": []}
    for _ in range(repeats):
        t0 = time.perf_counter()
        jac = np.asarray(jax.block_until_ready(jac_fn(model, params)))
        t1 = time.perf_counter()
        idx = np.concatenate([bonds[:, :1] * nd + np.arange(nd), bonds[:, 1:] * nd + np.arange(nd)], axis=1)
        rows = np.broadcast_to(idx[:, :, None], jac.shape).ravel()
        cols = np.broadcast_to(idx[:, None, :], jac.shape).ravel()
        K = sp.coo_matrix((jac.ravel(), (rows, cols)), shape=(ndof, ndof)).tocsc()  # duplicates summed
        K_f = K[:, fi]
        K_ff = K_f[fi, :].tocsc()
        K_fp = K[:, pi][fi, :]
        t2 = time.perf_counter()
        lu = spla.splu(K_ff, permc_spec="COLAMD")
        t3 = time.perf_counter()
        fill = int(lu.L.nnz + lu.U.nnz)
        u_f = lu.solve(-(K_fp @ u_p[pi]))
        u = u_p.copy()
        u[fi] = u_f
        gen = -(K @ u).reshape(-1, nd)  # internal forces
        reaction = float(system.reaction(gen))
        t4 = time.perf_counter()
        for key, t in zip(res, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
            res[key].append(t)
        del lu
        if sum(map(sum, res.values())) > budget:
            break
    out = {k: spread(v) for k, v in res.items()}
    out["repeats"] = len(res["factor"])
    total = [sum(x) for x in zip(*res.values())]
    fs = [a + b for a, b in zip(res["factor"], res["solve"])]
    out.update(total=spread(total), factor_solve=spread(fs), jacobians_compile_s=jac_first - min(res["jacobians"]),
               stiffness=reaction / system.delta, dofs=int(ndof), free_dofs=int(fi.size), nnz=int(K.nnz),
               nnz_ff=int(K_ff.nnz), fill_nnz=fill, ordering="COLAMD", factor_memory_MB=float(fill * 12 / 2**20),
               residual=float(np.linalg.norm(K_ff @ u_f + K_fp @ u_p[pi]) / np.linalg.norm(K_fp @ u_p[pi])))
    if dsm_matvec_check:
        # the assembled matrix against the DSM operator: K v == -(jvp of the forces) v
        v = np.random.default_rng(1).normal(size=(model.n, nd))

        def f(w):
            return dsm.operator.internal_forces(model, params, w)[0]

        jv = np.asarray(jax.jvp(f, (jnp.zeros((model.n, nd)),), (jnp.asarray(v),))[1]).ravel()
        kv = K @ v.ravel()
        out["operator_check"] = float(np.linalg.norm(kv + jv) / np.linalg.norm(kv))
    return out


# ---------------------------------------------------------------------------------------------------- one size
def run_size(n, args, jaxbpm, out_rows):
    import numpy as np

    from jaxbpm.physics.model import default_params

    rec = {"n_requested": n}
    t0 = time.perf_counter()
    sample, rec["sample_source"] = cached_box(n, args.seed, args.cache_dir)
    rec["generate_s"] = time.perf_counter() - t0
    rec["particles"], rec["bonds"] = sample.n_particles, sample.n_bonds
    params = default_params(sample)
    scene = jaxbpm.scenes.UniaxialCompression(strain=args.strain, boundary="layers")
    fixed, driven = scene.layers(sample)
    rec["clamped"] = {"fixed": int(fixed.sum()), "driven": int(driven.sum())}
    log(f"== n={sample.n_particles} bonds={sample.n_bonds} (generated in {rec['generate_s']:.1f} s)")
    base = {"particles": sample.n_particles, "bonds": sample.n_bonds}

    # ---- DEM, bonds only (the reference)
    dem = None
    if sample.n_particles <= args.dem_max:
        r = jaxbpm.solve(sample, scene, "dem")
        dem = {"stiffness": r.stiffness, "compile_s": r.compile_time, "run_s": r.run_time, "wall_s": r.wall_time,
               "steps": r.stats["steps"], "steps_per_s": r.stats["steps_per_second"], "dt": r.stats["dt"]}
        log(f"  DEM bonds: K={r.stiffness:.6g}  compile {r.compile_time:.2f} s  run {r.run_time:.2f} s "
            f"({dem['steps']} steps)  wall {r.wall_time:.2f} s")
    else:
        log(f"  DEM skipped: {sample.n_particles} particles > --dem-max {args.dem_max}")
    rec["dem"] = dem
    dem3 = None
    if args.dem3_max and sample.n_particles <= min(args.dem3_max, args.dem_max):
        scene3 = jaxbpm.scenes.UniaxialCompression(strain=args.strain, boundary="layers", rotations=False)
        r = jaxbpm.solve(sample, scene3, "dem")
        dem3 = {"stiffness": r.stiffness, "compile_s": r.compile_time, "run_s": r.run_time, "wall_s": r.wall_time,
                "steps": r.stats["steps"]}
        log(f"  DEM 3 DOF: K={r.stiffness:.6g}  run {r.run_time:.2f} s")
    rec["dem_3dof"] = dem3
    if dem is not None:
        out_rows.append({**base, "method": "DEM (6 DOF)", "compile_s": dem["compile_s"], "run_s": dem["run_s"],
                         "wall_s": dem["wall_s"], "K": dem["stiffness"], "dK_vs_DEM_%": 0.0,
                         "iters": f"{dem['steps']} steps"})
    if dem3 is not None:
        out_rows.append({**base, "method": "DEM (3 DOF)", "compile_s": dem3["compile_s"], "run_s": dem3["run_s"],
                         "wall_s": dem3["wall_s"], "K": dem3["stiffness"],
                         "dK_vs_DEM_%": 100 * (dem3["stiffness"] / dem["stiffness"] - 1) if dem else "",
                         "iters": f"{dem3['steps']} steps"})

    # ---- DSM linear: configurations (keys 6 and 3 are the library's defaults)
    rec["dsm"] = {}
    configs = [(6, "DSM lin 6 DOF", dict(dofs=6)),
               ("6-fast", f"DSM lin 6 DOF stol {args.stiffness_tol:g}", dict(dofs=6, stiffness_tol=args.stiffness_tol)),
               ("6-jacobi", "DSM lin 6 DOF Jacobi", dict(dofs=6, preconditioner="jacobi")),
               (3, "DSM lin 3 DOF", dict(dofs=3))]
    for key, label, kw in configs:
        dofs = kw["dofs"]
        runs = []
        for _ in range(args.repeats):
            # the residual-converged solve (stiffness_tol=None unless a configuration sets it), compared with splu
            runs.append(jaxbpm.solve(sample, scene, "dsm", linear_tol=args.linear_tol, throw=False,
                                     **{"stiffness_tol": None, **kw}))
        r0 = runs[0]
        d = {"label": label, "options": kw, "stiffness": r0.stiffness, "compile_s": r0.compile_time,
             "compile_s_later_calls": [r.compile_time for r in runs[1:]],
             "run_s": spread([r.run_time for r in runs]), "wall_s_first": r0.wall_time,
             "wall_s": spread([r.wall_time for r in runs]), "residual": r0.stats["residual"],
             "iterations": r0.stats["iterations"], "preconditioner": r0.stats["preconditioner"],
             "aggregates": r0.stats["aggregates"], "stiffness_boundary": r0.stats["stiffness_boundary"],
             "converged": bool(r0.stats["converged"]), "free_dofs": r0.stats["free_dofs"],
             "stiffness_spread": float(np.ptp([r.stiffness for r in runs]) / abs(r0.stiffness)),
             # once per sample, outside the run time: the parameter-independent bond Jacobians and preconditioner
             # parts (dsm.BondGeometry); the first call also compiles them
             "setup_s_first": r0.stats.get("setup_time"),
             "setup_s": min((r.stats.get("setup_time", 0.0) for r in runs[1:]), default=r0.stats.get("setup_time"))}
        ref = dem if dofs == 6 else dem3  # the DEM of the same model
        if dem is not None:
            d["dK_vs_DEM"] = r0.stiffness / dem["stiffness"] - 1
            d["speedup_run_vs_DEM"] = dem["run_s"] / d["run_s"]["min"]
            d["speedup_run_vs_DEM_median"] = dem["run_s"] / d["run_s"]["median"]
            d["speedup_wall_vs_DEM"] = dem["wall_s"] / r0.wall_time
        if dem3 is not None and dofs == 3:
            d["dK_vs_DEM_3dof"] = r0.stiffness / dem3["stiffness"] - 1
            d["speedup_run_vs_DEM_3dof"] = dem3["run_s"] / d["run_s"]["min"]
        rec["dsm"][key] = d
        log(f"  {label}: K={r0.stiffness:.6g}  compile {r0.compile_time:.2f} s  setup {d['setup_s']:.3f} s  "
            f"run min {d['run_s']['min']:.3f} s  "
            f"wall {r0.wall_time:.2f} s  CG {d['iterations']} it ({d['preconditioner']}, {d['aggregates']} aggregates)"
            + (f"  {d['speedup_run_vs_DEM']:.1f}x DEM run" if dem is not None else ""))
        out_rows.append({**base, "method": label, "compile_s": r0.compile_time, "setup_s": d["setup_s"],
                         "run_s": d["run_s"]["min"], "run_med_s": d["run_s"]["median"], "wall_s": r0.wall_time,
                         "K": r0.stiffness,
                         "dK_vs_DEM_%": 100 * d["dK_vs_DEM"] if dem else "",
                         "dK_matched_%": 100 * (r0.stiffness / ref["stiffness"] - 1) if ref else "",
                         "x_DEM_run": d.get("speedup_run_vs_DEM", ""), "x_DEM_wall": d.get("speedup_wall_vs_DEM", ""),
                         "iters": f"{d['iterations']} CG"})

    # ---- sparse direct solve of the linear 6-DOF system
    splu = None
    if sample.n_particles <= args.splu_max:
        system = LinearSystem(sample, scene, params, 6)
        splu = splu_solve(system, args.repeats, args.splu_budget)
        d6 = rec["dsm"][6]
        splu["dK_vs_DSM6"] = splu["stiffness"] / d6["stiffness"] - 1
        splu["dsm_speedup_total"] = splu["total"]["min"] / d6["run_s"]["min"]
        splu["dsm_speedup_factor_solve"] = splu["factor_solve"]["min"] / d6["run_s"]["min"]
        splu["dsm_fast_speedup_total"] = splu["total"]["min"] / rec["dsm"]["6-fast"]["run_s"]["min"]
        splu["dsm_jacobi_speedup_total"] = splu["total"]["min"] / rec["dsm"]["6-jacobi"]["run_s"]["min"]
        splu["dsm3_speedup_total"] = splu["total"]["min"] / rec["dsm"][3]["run_s"]["min"]
        log(f"  splu: K={splu['stiffness']:.9g} (vs DSM6 {splu['dK_vs_DSM6']:.2e})  jac "
            f"{splu['jacobians']['min']:.3f} s  assembly {splu['assembly']['min']:.3f} s  factor "
            f"{splu['factor']['min']:.2f} s  solve {splu['solve']['min']:.3f} s  fill {splu['fill_nnz']:.3g}  "
            f"DSM6 speed-up {splu['dsm_speedup_total']:.2f}x")
        out_rows.append({**base, "method": "splu 6 DOF", "run_s": splu["total"]["min"], "run_med_s": splu["total"]["median"], "K": splu["stiffness"],
                         "dK_vs_DEM_%": 100 * (splu["stiffness"] / dem["stiffness"] - 1) if dem else "",
                         "x_DEM_run": dem["run_s"] / splu["total"]["min"] if dem else "", "iters": "direct"})
    else:
        log(f"  splu skipped: {sample.n_particles} particles > --splu-max {args.splu_max}")
    rec["splu"] = splu

    # ---- contacts: nonlinear DSM vs DEM
    rec["contacts"] = None
    if not args.no_contacts and n in args.contact_sizes:
        scene_c = jaxbpm.scenes.UniaxialCompression(strain=args.strain, boundary="layers", contacts=True)
        c = {}
        if sample.n_particles <= args.dem_max:
            r = jaxbpm.solve(sample, scene_c, "dem")
            c["dem"] = {"stiffness": r.stiffness, "compile_s": r.compile_time, "run_s": r.run_time,
                        "wall_s": r.wall_time, "steps": r.stats["steps"], "reallocations": r.stats["reallocations"],
                        "contact_capacity": r.stats["contact_capacity"]}
            log(f"  DEM contacts: K={r.stiffness:.6g}  compile {r.compile_time:.2f} s  run {r.run_time:.2f} s")
        runs, tn = [], time.perf_counter()
        while len(runs) < args.nonlinear_repeats and (not runs or time.perf_counter() - tn < args.nonlinear_budget):
            runs.append(jaxbpm.solve(sample, scene_c, "dsm", throw=False))
        r0 = runs[0]
        c["dsm"] = {"stiffness": r0.stiffness, "compile_s": spread([r.compile_time for r in runs]),
                    "run_s": spread([r.run_time for r in runs]), "wall_s": spread([r.wall_time for r in runs]),
                    "newton_iterations": r0.stats["iterations"], "converged": bool(r0.stats["converged"]),
                    "residual": r0.stats["residual"], "contact_candidates": r0.stats["contacts"],
                    "load_steps": r0.stats["load_steps"], "dofs": r0.stats["dofs"], "repeats": len(runs)}
        log(f"  DSM nonlinear: K={r0.stiffness:.6g}  compile {r0.compile_time:.2f} s  run "
            f"{c['dsm']['run_s']['min']:.2f} s  Newton {r0.stats['iterations']}  converged {r0.stats['converged']}")
        d6, dn = rec["dsm"][6], c["dsm"]
        c["contacts_effect_dsm"] = dn["stiffness"] / d6["stiffness"] - 1
        c["cost_dsm_run_ratio"] = dn["run_s"]["min"] / d6["run_s"]["min"]
        if "dem" in c:
            c["contacts_effect_dem"] = c["dem"]["stiffness"] / dem["stiffness"] - 1
            c["cost_dem_run_ratio"] = c["dem"]["run_s"] / dem["run_s"]
            c["dK_dsm_vs_dem"] = dn["stiffness"] / c["dem"]["stiffness"] - 1
            c["speedup_run"] = c["dem"]["run_s"] / dn["run_s"]["min"]
            c["speedup_wall"] = c["dem"]["wall_s"] / r0.wall_time
            out_rows.append({**base, "method": "DEM +contacts", "compile_s": c["dem"]["compile_s"],
                             "run_s": c["dem"]["run_s"], "wall_s": c["dem"]["wall_s"], "K": c["dem"]["stiffness"],
                             "dK_vs_DEM_%": 100 * c["contacts_effect_dem"], "iters": f"{c['dem']['steps']} steps"})
        out_rows.append({**base, "method": "DSM nonlin +contacts", "compile_s": r0.compile_time,
                         "run_s": dn["run_s"]["min"], "run_med_s": dn["run_s"]["median"], "wall_s": r0.wall_time,
                         "K": dn["stiffness"], "dK_vs_DEM_%": 100 * (dn["stiffness"] / dem["stiffness"] - 1) if dem
                         else "", "dK_matched_%": 100 * c["dK_dsm_vs_dem"] if "dem" in c else "",
                         "x_DEM_run": c.get("speedup_run", ""), "x_DEM_wall": c.get("speedup_wall", ""),
                         "iters": f"{dn['newton_iterations']} Newton"})
        rec["contacts"] = c
    return rec


# ---------------------------------------------------------------------------------------------------- goals, plot
def extrapolate_splu(results) -> None:
    """For sizes where splu was skipped: fill-in and factorisation time from a power law in the free DOFs through
    the two largest measured sizes (an estimate, marked as such; never a measurement)."""
    import numpy as np

    done = [r for r in results if r["splu"]]
    if len(done) < 2:
        return
    a, b = done[-2]["splu"], done[-1]["splu"]
    for r in results:
        if r["splu"] is not None:
            continue
        nfree = r["dsm"][6]["free_dofs"]
        est = {"note": f"extrapolated (power law in free DOFs through the {done[-2]['particles']} and "
                       f"{done[-1]['particles']} particle runs), not measured"}
        for key, get in (("fill_nnz", lambda s: s["fill_nnz"]), ("factor_s", lambda s: s["factor"]["min"]),
                         ("total_s", lambda s: s["total"]["min"])):
            slope = np.log(get(b) / get(a)) / np.log(b["free_dofs"] / a["free_dofs"])
            est[key] = float(get(b) * (nfree / b["free_dofs"]) ** slope)
            est[key + "_exponent"] = float(slope)
        est["factor_memory_GB"] = est["fill_nnz"] * 12 / 2**30
        est["dsm_speedup_total"] = est["total_s"] / r["dsm"][6]["run_s"]["min"]
        r["splu_extrapolated"] = est


def evaluate_goals(results) -> dict:
    g = {}
    split = [(r["particles"], r["splu"]) for r in results if r["splu"]]
    near3k = [s for p, s in split if 2500 <= p <= 3500]
    if near3k:
        s = near3k[0]
        g["dsm6_20x_faster_than_splu_at_3k"] = {"met": s["dsm_speedup_total"] >= 20,
                                                "speedup_total": s["dsm_speedup_total"],
                                                "speedup_factor_solve_only": s["dsm_speedup_factor_solve"]}
    if len(split) > 1:
        sp = [s["dsm_speedup_total"] for _, s in split]
        g["dsm6_lead_over_splu_grows_with_size"] = {
            "met": all(b > a for a, b in zip(sp, sp[1:])), "particles": [p for p, _ in split], "speedups": sp}
    for dofs in (6, "6-fast", 3):
        rows = [(r["particles"], r["dsm"][dofs]) for r in results if r["dem"] is not None]
        if rows:
            g[f"dsm{dofs}_100x_faster_than_dem_within_1pct"] = {
                "met": all(d["speedup_run_vs_DEM"] >= 100 and abs(d["dK_vs_DEM"]) <= 0.01 for _, d in rows),
                "per_size": [{"particles": p, "speedup_run": d["speedup_run_vs_DEM"],
                              "speedup_wall": d["speedup_wall_vs_DEM"], "dK_vs_DEM": d["dK_vs_DEM"],
                              **({"dK_vs_DEM_3dof": d["dK_vs_DEM_3dof"]} if "dK_vs_DEM_3dof" in d else {})}
                             for p, d in rows]}
    return g


def plot(results, path, note):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    series = {
        "DEM bonds (run)": ("C0", "o", "-", lambda r: r["dem"] and r["dem"]["run_s"]),
        "DSM linear 6 DOF (run, min)": ("C1", "s", "-", lambda r: r["dsm"][6]["run_s"]["min"]),
        "DSM linear 3 DOF (run, min)": ("C2", "^", "-", lambda r: r["dsm"][3]["run_s"]["min"]),
        "splu 6 DOF (Jacobians+assembly+factor+solve)": ("C3", "D", "-", lambda r: r["splu"] and
                                                        r["splu"]["total"]["min"]),
        "splu 6 DOF (factor+solve)": ("C3", "d", ":", lambda r: r["splu"] and r["splu"]["factor_solve"]["min"]),
        "DSM linear 6 DOF, stiffness_tol (run, min)": ("C1", "s", ":", lambda r: r["dsm"]["6-fast"]["run_s"]["min"]),
        "DSM linear 6 DOF, block-Jacobi (run, min)": ("C6", "s", "--", lambda r: r["dsm"]["6-jacobi"]["run_s"]["min"]),
        "DEM + contacts (run)": ("C4", "o", "--", lambda r: r["contacts"] and r["contacts"].get("dem", {}).get(
            "run_s")),
        "DSM nonlinear + contacts (run, min)": ("C5", "v", "--", lambda r: r["contacts"] and r["contacts"]["dsm"][
            "run_s"]["min"]),
        "DEM bonds (wall)": ("C0", "o", ":", lambda r: r["dem"] and r["dem"]["wall_s"]),
        "DSM linear 6 DOF (wall, 1st call)": ("C1", "s", "-.", lambda r: r["dsm"][6]["wall_s_first"]),
    }
    fig, ax = plt.subplots(figsize=(12, 6))
    for label, (color, marker, ls, get) in series.items():
        pts = [(r["particles"], get(r)) for r in results]
        pts = [(p, t) for p, t in pts if t]
        if pts:
            p, t = np.array(pts).T
            ax.plot(p, t, color=color, marker=marker, ls=ls, label=label, alpha=0.9 if ls == "-" else 0.7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("particles")
    ax.set_ylabel("time [s]")
    ax.set_title("uniaxial compression, 0.2 % strain, clamped layers: time per method")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.text(0.01, 0.005, note, fontsize=6.5, alpha=0.8)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    from jaxbpm.io import atomic_write

    return atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=130, format="png"))


# ---------------------------------------------------------------------------------------------------- main
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=None, help=f"particles (default {DEFAULT_SIZES})")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--strain", type=float, default=0.002)
    ap.add_argument("--dem-max", type=int, default=50000, help="skip the DEM above this many particles")
    ap.add_argument("--dem3-max", type=int, default=10000,
                    help="run a rotation-free (3 DOF) DEM, the matched reference of the 3-DOF DSM, up to this many "
                         "particles (0: never)")
    ap.add_argument("--splu-max", type=int, default=10000,
                    help="skip splu above this many particles (its fill-in grows too fast: 50k would not fit in RAM)")
    ap.add_argument("--splu-budget", type=float, default=60.0,
                    help="stop repeating splu once its repeats took this long [s] (it always runs once)")
    ap.add_argument("--contact-sizes", type=int, nargs="*", default=None,
                    help="requested sizes with the contact comparison (default 2000 10000)")
    ap.add_argument("--no-contacts", action="store_true", help="skip the contact comparison")
    ap.add_argument("--repeats", type=int, default=3, help="timed repeats of DSM and splu (DEM runs once)")
    ap.add_argument("--nonlinear-repeats", type=int, default=3,
                    help="repeats of the nonlinear DSM (the first one compiles)")
    ap.add_argument("--nonlinear-budget", type=float, default=60.0,
                    help="stop repeating the nonlinear DSM once its repeats took this long [s] (it always runs once)")
    ap.add_argument("--cache-dir", default=None,
                    help="load the generated samples from (or save them to) this folder (box_<n>_seed<s>.h5)")
    ap.add_argument("--linear-tol", type=float, default=1e-6)
    ap.add_argument("--stiffness-tol", type=float, default=1e-3,
                    help="stiffness_tol of the 'fast' 6-DOF DSM configuration")
    ap.add_argument("--threads", type=int, default=1, help="cores to use (default 1)")
    ap.add_argument("--cpu", type=int, default=None, help="core to pin to with one thread (default: least busy)")
    ap.add_argument("--quick", action="store_true", help=f"smoke run: sizes {QUICK_SIZES}, 2 repeats")
    ap.add_argument("--out", default="results/dsm_vs_dem.json")
    ap.add_argument("--png", default=None, help="plot (default: --out with .png)")
    args = ap.parse_args(argv)
    if args.quick:
        args.sizes = args.sizes or QUICK_SIZES
        args.contact_sizes = args.contact_sizes if args.contact_sizes is not None else args.sizes
        args.repeats = min(args.repeats, 2)
        args.nonlinear_repeats = 1
        if args.out == "results/dsm_vs_dem.json":
            args.out = "results/dsm_vs_dem_quick.json"
    args.sizes = args.sizes or DEFAULT_SIZES
    args.contact_sizes = args.contact_sizes if args.contact_sizes is not None else [2000, 10000]
    png = args.png or os.path.splitext(args.out)[0] + ".png"

    load_before = machine_load(1.0)
    cpu = pin(args.cpu, args.threads)
    enable_x64()

    import jaxbpm

    log(f"pinned to core {cpu}; core load before: {load_before}")
    t_start = time.perf_counter()
    results, rows = [], []
    for n in args.sizes:
        results.append(run_size(n, args, jaxbpm, rows))
    load_after = machine_load(1.0)
    extrapolate_splu(results)
    goals = evaluate_goals(results)

    columns = ["particles", "bonds", "method", "compile_s", "setup_s", "run_s", "run_med_s", "wall_s", "K", "dK_vs_DEM_%",
               "dK_matched_%", "x_DEM_run", "x_DEM_wall", "iters"]
    print("\nAll methods (run_s: min over repeats; DEM once; dK_matched: vs the DEM of the same model -- 3-DOF DEM "
          "for 3 DOF, DEM + contacts for the nonlinear DSM)")
    table(rows, columns)
    srows = [{"particles": r["particles"], "free_dofs": r["splu"]["free_dofs"], "nnz_ff": r["splu"]["nnz_ff"],
              "fill_nnz": r["splu"]["fill_nnz"], "jac_s": r["splu"]["jacobians"]["min"],
              "assembly_s": r["splu"]["assembly"]["min"], "factor_s": r["splu"]["factor"]["min"],
              "solve_s": r["splu"]["solve"]["min"], "splu_total_s": r["splu"]["total"]["min"],
              "DSM6_run_s": r["dsm"][6]["run_s"]["min"], "x_total": r["splu"]["dsm_speedup_total"],
              "x_f+s": r["splu"]["dsm_speedup_factor_solve"], "x_fast": r["splu"]["dsm_fast_speedup_total"],
              "x_DSM3": r["splu"]["dsm3_speedup_total"], "dK_vs_DSM6": r["splu"]["dK_vs_DSM6"],
              "op_check": r["splu"]["operator_check"]} for r in results if r["splu"]]
    if srows:
        print("\nsplu (SuperLU, COLAMD) on the same linear 6-DOF system; x_*: DSM speed-up = splu time / DSM run "
              "(total, factor+solve only, DSM with stiffness_tol, 3-DOF DSM)")
        table(srows, list(srows[0]))
    cont = [{"particles": r["particles"], "candidates": r["contacts"]["dsm"]["contact_candidates"],
             "K_DEM_c": r["contacts"].get("dem", {}).get("stiffness", ""), "K_DSM_c": r["contacts"]["dsm"]["stiffness"],
             "dK_DSM_vs_DEM_%": 100 * r["contacts"].get("dK_dsm_vs_dem", float("nan")),
             "contacts_effect_DEM_%": 100 * r["contacts"].get("contacts_effect_dem", float("nan")),
             "contacts_effect_DSM_%": 100 * r["contacts"]["contacts_effect_dsm"],
             "DEM_cost_x": r["contacts"].get("cost_dem_run_ratio", ""),
             "DSM_cost_x": r["contacts"]["cost_dsm_run_ratio"], "x_run": r["contacts"].get("speedup_run", ""),
             "x_wall": r["contacts"].get("speedup_wall", ""), "Newton": r["contacts"]["dsm"]["newton_iterations"],
             "converged": r["contacts"]["dsm"]["converged"]} for r in results if r["contacts"]]
    if cont:
        print("\nContacts (Hertz): stiffness change they cause, run-time cost factor (with / without), nonlinear DSM "
              "vs DEM")
        table(cont, list(cont[0]))
    print("\nGoals:")
    for k, v in goals.items():
        where = ""
        if "per_size" in v and "100x" in k:
            hit = [e["particles"] for e in v["per_size"] if e["speedup_run"] >= 100 and abs(e["dK_vs_DEM"]) <= 0.01]
            miss = [e["particles"] for e in v["per_size"] if e["particles"] not in hit]
            where = f" (met at {hit or 'no size'}, not at {miss or 'any size'})"
        print(f"  {k}: {'MET at every size' if v['met'] else 'NOT met at every size'}{where}")
    skipped = [r["particles"] for r in results if r["dem"] is None]
    if skipped:
        print(f"  DEM skipped for {skipped} particles (> --dem-max {args.dem_max})")
    for r in results:
        if r["splu"] is None:
            print(f"  splu skipped for {r['particles']} particles (> --splu-max {args.splu_max})", end="")
            e = r.get("splu_extrapolated")
            if e:
                print(f"; {e['note']}: fill {e['fill_nnz']:.3g} nnz (~{e['factor_memory_GB']:.2g} GB for the "
                      f"factors), factorisation ~{e['factor_s']:.3g} s, total ~{e['total_s']:.3g} s, i.e. DSM 6 DOF "
                      f"~{e['dsm_speedup_total']:.3g}x faster", end="")
            print()
    print(f"  machine load (busy fraction per core) before {load_before['cpu_busy']} after {load_after['cpu_busy']};"
          f" this run pinned to core {cpu}")

    settings = {k: v for k, v in vars(args).items()}
    out = {"benchmark": "dsm_vs_dem", "machine": {**machine_info(), "pinned_core": cpu, "load_before": load_before,
                                                  "load_after": load_after},
           "settings": settings, "total_time_s": time.perf_counter() - t_start, "results": results, "rows": rows,
           "splu_rows": srows, "contact_rows": cont, "goals": goals}
    print(json.dumps(out, indent=1, default=_json_default))
    path = write_json(args.out, json.loads(json.dumps(out, default=_json_default)))
    print(f"wrote {path}")
    note = (f"core {cpu} of {os.cpu_count()}, XLA 1 thread; load before {load_before['cpu_busy']} after "
            f"{load_after['cpu_busy']}; jax {machine_info()['jax']}")
    print(f"wrote {plot(results, png, note)}")
    return 0


def _json_default(o):
    import numpy as np

    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.bool_):
        return bool(o)
    return str(o)


if __name__ == "__main__":
    sys.exit(main())
