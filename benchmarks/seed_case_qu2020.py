"""Qu et al. 2020's SiC ceramic, in 3D: bond strengths calibrated to a flexural strength of 0.78 GPa and a compressive
strength of 2 GPa, side by side with the paper's Tables 4-6.

Parameters (the paper's Table 3, PFC's parallel bond, deformability method), translated through
``jaxbpm.interop.conventions.from_pfc``: effective modulus 211 GPa and normal-to-shear stiffness ratio 1.21 for bonds
and particles (bond E = 211 GPa for touching particles, bond nu = 1.21 / 2 - 1 = -0.395, bond radius = the smaller
particle's), radii uniform in 4.5-6.75 um, density 2600 kg/m^3, friction 0.7. Specimens: a cylinder (UCS, aspect 2)
and a beam (three-point bending, span 4 x depth); the paper's are 2D, 66 743 and 22 507 discs.

The calibration is :func:`jaxbpm.calibrate.lab` with the strength targets only (the deformation parameters are
adopted, as in the paper): Qu et al.'s estimates 1 and 2, then Gauss-Newton steps in log space. A "model" is one
parameter set (a UCS run plus a bending run), Qu et al.'s count. Then the size study: the UCS of cylinders from 250
particles up at the calibrated bond strengths, so that users know what size to calibrate on.

    python benchmarks/seed_case_qu2020.py                 # ~60k + ~20k particles: hours on one core
    python benchmarks/seed_case_qu2020.py --quick         # ~3k + ~2k particles
    python benchmarks/seed_case_qu2020.py --ucs-n 8000 --tpb-n 4000 --sizes 250 1000 4000 16000
    python benchmarks/seed_case_qu2020.py --2d [--quick]  # the paper's 2D case (seed_case_qu2020_2d.py)
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))
from _common import enable_x64, machine_info, table, write_json  # noqa: E402

# Qu et al. 2020: Table 4 (original scheme), Table 5 (simplified scheme), Table 6 (efficiency)
QU2020 = {"original": {"iterations": 6, "models": 19, "flexural_error": -0.027, "ucs_error": -0.002,
                       "best_reported": "2.7 % (TPBT), 1.6 % (UCT)"},
          "simplified": {"iterations": 3, "models": 4, "flexural_error": 0.015, "ucs_error": -0.030,
                         "best_reported": "1.5 % (TPBT), 3.0 % (UCT)"}}
TARGETS = {"flexural": 0.78e9, "ucs": 2.0e9}


def sic(n: int, shape: str, seed: int = 0):
    """A bonded SiC specimen of ``n`` particles (Table 3, translated from PFC's parallel bond)."""
    import numpy as np

    import jaxbpm
    from jaxbpm.interop.conventions import from_pfc

    r_mean, spread = 5.625e-6, 0.2  # 4.5-6.75 um uniform
    bond = from_pfc(r_mean, r_mean, 2 * r_mean, emod=211e9, kratio=1.21, pb_rmul=1.0, pb_ten=5e9, pb_coh=7.8e8)
    mats = {"E": float(bond.E), "nu": float(bond.nu), "tensile_strength": 5e9, "shear_strength": 7.8e8}
    pm = {"density": 2600.0, "E": 211e9, "nu": float(np.clip(bond.nu, -0.99, 0.49)), "friction": 0.7}
    gen = {"cylinder": jaxbpm.generate.cylinder, "beam": jaxbpm.generate.beam}[shape]
    return gen(n, seed=seed, mean_radius=r_mean, radius_spread=spread, materials=mats,
               particle_material=pm, bond_radius_ratio=1.0).largest_cluster()


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if "--2d" in argv:
        import seed_case_qu2020_2d

        return seed_case_qu2020_2d.main(argv)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ucs-n", type=int, default=60000, dest="ucs_n")
    ap.add_argument("--tpb-n", type=int, default=20000, dest="tpb_n")
    ap.add_argument("--sizes", type=int, nargs="*", default=[250, 1000, 4000, 16000, 60000],
                    help="cylinder sizes of the size study (at the calibrated strengths)")
    ap.add_argument("--tol", type=float, default=0.05)
    ap.add_argument("--max-iterations", type=int, default=6, dest="max_iterations")
    ap.add_argument("--transits", type=float, default=30.0)
    ap.add_argument("--quick", action="store_true", help="3000 + 2000 particles, sizes 250 1000 3000")
    ap.add_argument("--out", default="results/seed_case_qu2020.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.ucs_n, args.tpb_n, args.sizes = 3000, 2000, [250, 1000, 3000]
        if args.out == "results/seed_case_qu2020.json":
            args.out = "results/seed_case_qu2020_quick.json"
    enable_x64()
    import jaxbpm
    from jaxbpm.calibrate import lab
    from jaxbpm.physics.model import default_params

    t_all = time.perf_counter()
    t0 = time.perf_counter()
    cyl, beam = sic(args.ucs_n, "cylinder"), sic(args.tpb_n, "beam", seed=1)
    gen_time = time.perf_counter() - t0
    print(f"cylinder {cyl.n_particles} particles / {cyl.n_bonds} bonds, beam {beam.n_particles} / {beam.n_bonds} "
          f"({gen_time:.1f} s to generate); bond E {float(cyl.materials.E[0]):.4g} Pa, bond nu "
          f"{float(cyl.materials.nu[0]):.3f}", flush=True)
    res = lab({"ucs": cyl, "flexural": beam}, TARGETS, tol=args.tol, max_iterations=args.max_iterations,
              solve_options={"transits": args.transits}, progress=True)
    st = res.stages["strength"]
    sets = st.evaluations // 2
    print(res.table(), flush=True)
    rows = [{"scheme": "jaxbpm lab (estimates + Gauss-Newton)", "iterations": st.iterations, "models": sets,
             "flexural_error": res.achieved["flexural"][1], "ucs_error": res.achieved["ucs"][1],
             "converged": res.converged, "wall_s": res.wall_time}]
    for name, q in QU2020.items():
        rows.append({"scheme": f"Qu et al. 2020, {name}", "iterations": q["iterations"], "models": q["models"],
                     "flexural_error": q["flexural_error"], "ucs_error": q["ucs_error"], "converged": True})
    table([{**r, "flexural_%": 100 * r["flexural_error"], "ucs_%": 100 * r["ucs_error"]} for r in rows],
          ["scheme", "iterations", "models", "flexural_%", "ucs_%", "converged", "wall_s"])

    # what size to calibrate on: the UCS at the calibrated strengths against the cylinder's particle count
    sizes = []
    p_cal = {"bond_tensile_strength": res.params["bond_tensile_strength"],
             "bond_shear_strength": res.params["bond_shear_strength"]}
    for n in args.sizes:
        t0 = time.perf_counter()
        s = cyl if n == args.ucs_n else sic(n, "cylinder", seed=2)
        p = {**default_params(s), **{k: [v] for k, v in p_cal.items()}}
        r = jaxbpm.solve(s, jaxbpm.scenes.UniaxialCompression.to_failure(strain=0.02), "dem", params=p,
                         transits=args.transits, throw=False)
        sizes.append({"particles": s.n_particles, "ucs": r.stats.get("strength"),
                      "ucs_vs_target": r.stats.get("strength", float("nan")) / TARGETS["ucs"] - 1,
                      "wall_s": time.perf_counter() - t0})
        print(f"size {s.n_particles}: UCS {sizes[-1]['ucs']:.4g} Pa ({100 * sizes[-1]['ucs_vs_target']:+.1f} % of "
              f"the target), {sizes[-1]['wall_s']:.1f} s", flush=True)
    table(sizes, ["particles", "ucs", "ucs_vs_target", "wall_s"])
    write_json(args.out, {"benchmark": "seed_case_qu2020", "machine": machine_info(), "settings": vars(args),
                          "specimens": {"ucs": [cyl.n_particles, cyl.n_bonds], "tpb": [beam.n_particles,
                                                                                     beam.n_bonds]},
                          "targets": TARGETS, "params": res.params, "achieved": res.achieved,
                          "history": [{"kind": r["kind"], "values": r["values"].tolist(),
                                       "errors": r["errors"].tolist()} for r in st.history.rows],
                          "comparison": rows, "size_study": sizes, "qu2020": QU2020,
                          "total_time_s": time.perf_counter() - t_all})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
