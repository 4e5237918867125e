"""Macroscopic Poisson's ratio against the bond Poisson ratio and the bond radius ratio (DSM, STE, DEM checks).

A bonded cylinder (``--n`` particles, aspect 2) in uniaxial compression (0.1 %, clamped end layers): the DSM's
Poisson ratio (lateral strain of the middle third) over a grid of bond Poisson ratios and bond radius ratios, the
STE's beside it, and the DEM at a few points (it must agree with the DSM: the same model). Prints the table, saves
JSON and a chart (``results/poisson.png``) of what range of Poisson ratios a bonds-only BPM can be calibrated to.

    python benchmarks/poisson.py [--n 3000] [--quick]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(__file__))
from _common import enable_x64, machine_info, save_png, table, write_json  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=3000)
    ap.add_argument("--bond-nu", type=float, nargs="+", default=[-0.5, -0.25, 0.0, 0.15, 0.3, 0.45, 0.49],
                    dest="bond_nu")
    ap.add_argument("--ratios", type=float, nargs="+", default=[0.3, 0.5, 0.7, 1.0])
    ap.add_argument("--dem-points", type=int, default=3, help="DEM checks (bond nu values at ratio 0.5)")
    ap.add_argument("--quick", action="store_true", help="800 particles, a coarser grid, one DEM check")
    ap.add_argument("--out", default="results/poisson.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.n, args.bond_nu, args.ratios, args.dem_points = 800, [-0.5, 0.0, 0.3, 0.49], [0.3, 0.5, 1.0], 1
        if args.out == "results/poisson.json":
            args.out = "results/poisson_quick.json"
    enable_x64()
    import numpy as np

    import jaxbpm
    from jaxbpm.physics.model import default_params

    base = jaxbpm.generate.cylinder(args.n, seed=0, mean_radius=1e-3,
                                    materials={"E": 1e9, "nu": 0.25}).largest_cluster()
    scene = jaxbpm.scenes.UniaxialCompression(strain=1e-3)
    rows = []
    for ratio in args.ratios:
        s = base.replace(bond_radius_ratio=ratio)
        p0 = default_params(s)
        for k, nu_b in enumerate(args.bond_nu):
            p = {**p0, "bond_nu": np.full_like(np.asarray(p0["bond_nu"]), nu_b)}
            t0 = time.perf_counter()
            dsm = jaxbpm.solve(s, scene, method="dsm", params=p)
            t_dsm = time.perf_counter() - t0
            ste = jaxbpm.solve(s, scene, method="ste", params=p)
            row = {"ratio": ratio, "bond_nu": nu_b, "nu_dsm": dsm.poisson_ratio, "nu_ste": ste.poisson_ratio,
                   "E_dsm": dsm.youngs_modulus, "dsm_s": t_dsm}
            picks = np.linspace(0, len(args.bond_nu) - 1, args.dem_points).round().astype(int) if args.dem_points else []
            if ratio == 0.5 and k in picks:
                t0 = time.perf_counter()
                dem = jaxbpm.solve(s, scene, method="dem", params=p)
                row.update(nu_dem=dem.poisson_ratio, dem_vs_dsm=dem.poisson_ratio / dsm.poisson_ratio - 1,
                           dem_s=time.perf_counter() - t0)
            rows.append(row)
            print(f"ratio {ratio}  bond nu {nu_b:+.2f}: DSM {dsm.poisson_ratio:.4f}  STE {ste.poisson_ratio:.4f}"
                  + (f"  DEM {row['nu_dem']:.4f} ({100 * row['dem_vs_dsm']:+.2f} %)" if "nu_dem" in row else ""),
                  flush=True)
    table(rows, ["ratio", "bond_nu", "nu_dsm", "nu_ste", "nu_dem", "dem_vs_dsm", "E_dsm"])
    reach = {r: (min(x["nu_dsm"] for x in rows if x["ratio"] == r), max(x["nu_dsm"] for x in rows if x["ratio"] == r))
             for r in args.ratios}
    print("reachable macroscopic nu per bond radius ratio (DSM):",
          ", ".join(f"{r}: {lo:.3f}-{hi:.3f}" for r, (lo, hi) in reach.items()))

    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.5, 4.2))
    ax = fig.subplots()
    for r in args.ratios:
        sel = [x for x in rows if x["ratio"] == r]
        line, = ax.plot([x["bond_nu"] for x in sel], [x["nu_dsm"] for x in sel], "o-", label=f"DSM, r_b/R = {r}")
        ax.plot([x["bond_nu"] for x in sel], [x["nu_ste"] for x in sel], ":", color=line.get_color(), lw=1)
    dem = [x for x in rows if "nu_dem" in x]
    if dem:
        ax.plot([x["bond_nu"] for x in dem], [x["nu_dem"] for x in dem], "kx", ms=9, label="DEM (r_b/R = 0.5)")
    ax.set(xlabel="bond Poisson ratio (k_t / k_n = 1 / (2 (1 + nu_b)))", ylabel="macroscopic Poisson ratio",
           title=f"Poisson's ratio of a bonded cylinder ({base.n_particles} particles); dotted: STE")
    ax.legend(fontsize=7)
    png = os.path.splitext(args.out)[0] + ".png"
    save_png(fig, png, note=f"{machine_info()['device']}, float64")
    write_json(args.out, {"benchmark": "poisson", "machine": machine_info(), "settings": vars(args),
                          "particles": base.n_particles, "bonds": base.n_bonds, "results": rows,
                          "reach": {str(k): v for k, v in reach.items()}})
    print(f"wrote {args.out} and {png}")


if __name__ == "__main__":
    main()
