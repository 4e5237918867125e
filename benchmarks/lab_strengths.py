"""The staged laboratory calibration on large specimens: E, nu, UCS, BTS (and flexural strength) from wrong bonds.

Specimens of ``--n`` particles each: a bonded cylinder (aspect 2: UCS, and E and nu), a disc (aspect 0.5: BTS) and,
with ``--flexural``, a beam (three-point bending). The targets are what the same models give with known bond
parameters (E = 1 GPa, nu = 0.2, sigma_c = 4 MPa, tau_c = 8 MPa): E and nu by the DSM, the strengths by DEM failure
runs. :func:`jaxbpm.calibrate.lab` then starts from wrong parameters (E 3x low, nu 0.3, both strengths 10 MPa) and
is judged by its DEM runs: E and nu within 2 % (DEM check), strengths within 5 %, in how many parameter sets
(one set: one failure run per strength test, as Qu et al. 2020 count "models"; their Table 6: 19 models, 6
iterations). Prints the table and per-stage solves and wall times, saves JSON.

    python benchmarks/lab_strengths.py [--n 20000] [--flexural] [--quick]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))
from _common import enable_x64, machine_info, peak_rss_gib, write_json  # noqa: E402

TRUE = {"E": 1e9, "nu": 0.2, "tensile_strength": 4e6, "shear_strength": 8e6}
START = {"E": 3e8, "nu": 0.3, "tensile_strength": 1e7, "shear_strength": 1e7}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20_000, help="particles per specimen")
    ap.add_argument("--flexural", action="store_true", help="a bending beam and a flexural target as well")
    ap.add_argument("--transits", type=float, default=30.0)
    ap.add_argument("--quick", action="store_true", help="1000 particles per specimen")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    if args.quick:
        args.n = 1000
    out = args.out or f"results/lab_strengths{'_quick' if args.quick else ''}.json"
    enable_x64()
    import jaxbpm
    from jaxbpm.calibrate import lab
    from jaxbpm.sample import BondMaterials
    from jaxbpm.scenes import BrazilianDisc, ThreePointBending, UniaxialCompression

    t_all = time.perf_counter()
    t0 = time.perf_counter()
    specimens = {"ucs": jaxbpm.generate.cylinder(args.n, seed=0, materials=TRUE).largest_cluster(),
                 "bts": jaxbpm.generate.cylinder(args.n, seed=1, aspect=0.5, materials=TRUE).largest_cluster()}
    if args.flexural:
        specimens["flexural"] = jaxbpm.generate.beam(args.n, seed=2, materials=TRUE).largest_cluster()
    t_generate = time.perf_counter() - t0
    print("specimens:", {k: (s.n_particles, s.n_bonds) for k, s in specimens.items()},
          f"(generated in {t_generate:.1f} s)", flush=True)
    t0 = time.perf_counter()
    elastic = jaxbpm.solve(specimens["ucs"], UniaxialCompression(strain=1e-3), "dsm")
    scenes = {"ucs": UniaxialCompression.to_failure(strain=0.02), "bts": BrazilianDisc(),
              "flexural": ThreePointBending(strain=0.1)}
    targets = {"E": elastic.youngs_modulus, "nu": elastic.poisson_ratio}
    for key, sample in specimens.items():
        run = jaxbpm.solve(sample, scenes[key], "dem", transits=args.transits)
        targets[key] = run.stats["strength"]
        print(f"target {key}: {targets[key]:.5g} Pa ({run.wall_time:.1f} s)", flush=True)
    t_targets = time.perf_counter() - t0
    start = BondMaterials.create(**START)
    wrong = {k: s.replace(materials=start) for k, s in specimens.items()}
    t0 = time.perf_counter()
    res = lab(wrong, targets, solve_options={"transits": args.transits}, progress=True)
    t_lab = time.perf_counter() - t0
    print(res.table())
    strength_tests = [k for k in ("ucs", "bts", "flexural") if k in targets]
    runs = res.solves.get("strength (DEM failure runs)", 0)
    sets = runs // max(len(strength_tests), 1)
    errors = {k: err for k, (_, err) in res.achieved.items()}
    met = (res.converged and all(abs(errors[k]) <= 0.02 for k in ("E", "nu"))
           and all(abs(errors[k]) <= 0.05 for k in strength_tests))
    print(f"converged {res.converged}; parameter sets {sets} ({runs} failure runs); errors "
          + ", ".join(f"{k} {100 * e:+.2f} %" for k, e in errors.items())
          + f"; lab {t_lab:.0f} s, targets {t_targets:.0f} s, generation {t_generate:.0f} s", flush=True)
    write_json(out, {"benchmark": "lab_strengths", "machine": machine_info(), "n": args.n,
                     "specimens": {k: {"particles": s.n_particles, "bonds": s.n_bonds} for k, s in specimens.items()},
                     "targets": targets, "errors": errors, "converged": bool(res.converged),
                     "parameter_sets": sets, "failure_runs": runs, "solves": res.solves,
                     "params": {k: float(v) if hasattr(v, "__float__") else v for k, v in res.params.items()},
                     "true": TRUE, "start": START, "goal_met": bool(met), "lab_s": t_lab, "targets_s": t_targets,
                     "generate_s": t_generate, "total_s": time.perf_counter() - t_all, "peak_rss_gib": peak_rss_gib()})
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
