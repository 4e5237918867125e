"""The DSM-started DEM against the DEM from rest on the strength scenes: peak strength, wall time, steps.

Specimens of ``--n`` particles (as ``benchmarks/lab_strengths.py`` makes them: a cylinder for UCS, a disc for BTS, a
beam for three-point bending; bonds, Hertz-Mindlin contacts, breakage). Each scene runs once per start to compile,
then from rest and with ``start="elastic"`` at each loading rate of ``--transits`` (one compiled chunk for all:
``--chunk``), each ``--repeat`` times (the least wall time counts). The strength's spread over the loading rates
of the runs from rest is the run-to-run scatter the elastic start's difference is set against. Prints a table and
saves JSON.

    python benchmarks/elastic_start.py [--n 1000] [--scenes ucs bts flexural] [--transits 40 80 160]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import enable_x64, machine_info, write_json  # noqa: E402

TRUE = {"E": 1e9, "nu": 0.2, "tensile_strength": 4e6, "shear_strength": 8e6}


def specimens(n, which):
    import jaxbpm
    from jaxbpm.scenes import BrazilianDisc, ThreePointBending, UniaxialCompression

    make = {"ucs": lambda: (jaxbpm.generate.cylinder(n, seed=0, materials=TRUE).largest_cluster(),
                            UniaxialCompression.to_failure(strain=0.02)),
            "bts": lambda: (jaxbpm.generate.cylinder(n, seed=1, aspect=0.5, materials=TRUE).largest_cluster(),
                            BrazilianDisc()),
            "flexural": lambda: (jaxbpm.generate.beam(n, seed=2, materials=TRUE).largest_cluster(),
                                 ThreePointBending(strain=0.1))}
    return {k: make[k]() for k in which}


def run(sample, scene, transits, chunk, start, repeat=1, safety=None):
    import jaxbpm

    extra = {"start_safety": safety} if start == "elastic" and safety is not None else {}
    walls = []
    for _ in range(repeat):  # the same run again: its wall time is the least of the repeats (a shared machine)
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = jaxbpm.solve(sample, scene, "dem", transits=transits, chunk=chunk, start=start, **extra)
        walls.append(time.perf_counter() - t)
    wall = min(walls)
    st = res.stats
    first = float(np.nanmin(np.asarray(res.state.broken_time))) * st["speed"] / (st["speed"] * st["loading_time"])
    out = {"strength": st["strength"], "wall_s": wall, "walls_s": walls, "compile_s": res.compile_time,
           "steps": st["steps"],
           "peak_fraction": st["displacement_at_peak"] / (st["speed"] * st["loading_time"]),
           "first_break_fraction": first, "youngs_modulus": res.youngs_modulus, "stiffness": res.stiffness}
    if start == "elastic":
        info = st["elastic_start"]
        out.update({k: info.get(k) for k in ("fallback", "scale", "first_break_scale", "imbalance", "contact_share",
                                             "dsm_time", "time")})
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="particles per specimen")
    ap.add_argument("--scenes", nargs="+", default=["ucs", "bts", "flexural"])
    ap.add_argument("--transits", type=float, nargs="+", default=[40.0, 80.0, 160.0])
    ap.add_argument("--chunk", type=int, default=64, help="steps per compiled chunk (one program for every rate)")
    ap.add_argument("--repeat", type=int, default=2, help="runs of each case; the least wall time counts")
    ap.add_argument("--safety", type=float, default=None, help="start_safety (default: the DEM's)")
    ap.add_argument("--out", default="results/elastic_start.json")
    args = ap.parse_args(argv)
    enable_x64()
    rows = {}
    for key, (sample, scene) in specimens(args.n, args.scenes).items():
        print(f"{key}: {sample.n_particles} particles, {sample.n_bonds} bonds, {scene!r}", flush=True)
        first = {s: run(sample, scene, args.transits[0], args.chunk, s, safety=args.safety)
                 for s in ("rest", "elastic")}
        print(f"  first calls (compiling): rest {first['rest']['wall_s']:.1f} s, elastic "
              f"{first['elastic']['wall_s']:.1f} s", flush=True)
        runs = []
        for tr in args.transits:
            rest = run(sample, scene, tr, args.chunk, "rest", args.repeat)
            elastic = run(sample, scene, tr, args.chunk, "elastic", args.repeat, args.safety)
            runs.append({"transits": tr, "rest": rest, "elastic": elastic})
            print(f"  transits {tr:5.1f}: strength rest {rest['strength']:.5g} elastic {elastic['strength']:.5g} "
                  f"({100 * (elastic['strength'] / rest['strength'] - 1):+.2f} %); wall {rest['wall_s']:.2f} s / "
                  f"{elastic['wall_s']:.2f} s ({100 * elastic['wall_s'] / rest['wall_s']:.0f} %); steps "
                  f"{rest['steps']} / {elastic['steps']}; first break at {rest['first_break_fraction']:.3f} of the "
                  f"target (DSM {elastic.get('first_break_scale') or float('nan'):.3f}), peak at "
                  f"{rest['peak_fraction']:.3f}; E {rest['youngs_modulus']:.4g} / {elastic['youngs_modulus']:.4g}",
                  flush=True)
        strengths = np.array([r["rest"]["strength"] for r in runs])
        diffs = [r["elastic"]["strength"] / r["rest"]["strength"] - 1 for r in runs]
        walls = [r["elastic"]["wall_s"] / r["rest"]["wall_s"] for r in runs]
        scatter = float((strengths.max() - strengths.min()) / strengths.mean())
        rows[key] = {"particles": sample.n_particles, "bonds": sample.n_bonds, "scene": repr(scene), "first": first,
                     "runs": runs, "scatter_rest": scatter, "max_abs_diff": float(np.max(np.abs(diffs))),
                     "wall_ratio_median": float(np.median(walls))}
        print(f"  {key}: strength difference at most {100 * rows[key]['max_abs_diff']:.2f} % (scatter of the runs "
              f"from rest over the rates {100 * scatter:.2f} %); elastic wall / rest wall median "
              f"{100 * rows[key]['wall_ratio_median']:.0f} %", flush=True)
    write_json(args.out, {"benchmark": "elastic_start", "machine": machine_info(), "n": args.n, "safety": args.safety,
                          "transits": args.transits, "chunk": args.chunk, "scenes": rows})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
