"""The plots of a result (``jaxbpm.plots``) on a UCS run to failure: the figures of the README and the docs.

A bonded cylinder of ``--n`` particles (aspect 2; bond E = 1 GPa, nu = 0.2, tensile and shear strength 5 MPa;
Hertz-Mindlin contacts; ``UniaxialCompression.to_failure(strain=0.02)``, stopped at 70 % of the peak) is run
by the DEM; the DSM and the STE give the elastic modulus of the same sample (``UniaxialCompression(strain=0.002)``).
Writes

* ``docs/img/stress_strain.png``: ``dem.plot(); dsm.plot(ax=ax); ste.plot(ax=ax)`` (the curve, its peak, the line
  of E, the broken bonds; the DSM's and the STE's E beside it);
* ``docs/img/crack_pattern.png``: ``dem.plot_cracks(sample)`` (broken bonds by mode in the middle x-z section);
* ``docs/img/result_plots.png``: the two side by side (the README's figure);
* ``results/result_plots.json``: the numbers drawn.

    python benchmarks/result_plots.py [--n 1500] [--transits 30] [--out docs/img]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, os.path.dirname(__file__))
from _common import enable_x64, machine_info, write_json  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
MATERIALS = {"E": 1e9, "nu": 0.2, "tensile_strength": 5e6, "shear_strength": 5e6}


def solves(n: int, transits: float):
    """The sample and its DEM run to failure, DSM and STE solves (in this order, one process)."""
    import jaxbpm
    from jaxbpm.scenes import UniaxialCompression

    sample = jaxbpm.generate.cylinder(n, seed=0, materials=MATERIALS).largest_cluster()
    dem = jaxbpm.solve(sample, UniaxialCompression.to_failure(strain=0.02), "dem", transits=transits)
    elastic = UniaxialCompression(strain=0.002)
    return sample, dem, jaxbpm.solve(sample, elastic, "dsm"), jaxbpm.solve(sample, elastic, "ste")


def figures(sample, dem, dsm, ste, out: Path) -> list[Path]:
    """The three PNGs (see the module's docstring)."""
    from matplotlib.figure import Figure

    from jaxbpm import plots

    def curves(ax=None):
        ax = dem.plot(ax=ax)
        dsm.plot(ax=ax)
        ste.plot(ax=ax)
        ax.set_title(f"UCS to failure, {sample.n_particles} particles: stress-strain (jaxbpm.plots)", fontsize=9)
        return ax

    out.mkdir(parents=True, exist_ok=True)
    written = [plots.save(curves(), out / "stress_strain.png", dpi=110),
               plots.save(dem.plot_cracks(sample), out / "crack_pattern.png", dpi=110)]
    fig = Figure(figsize=(11.5, 6.2), layout="constrained")
    left, right = fig.subplots(1, 2, width_ratios=[1.5, 1])
    curves(left)
    dem.plot_cracks(sample, ax=right)
    written.append(plots.save(fig, out / "result_plots.png", dpi=90))
    return written


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1500, help="particles of the cylinder (before largest_cluster)")
    ap.add_argument("--transits", type=float, default=30.0, help="the DEM's loading time in elastic-wave transits")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "img", help="where the PNGs go")
    ap.add_argument("--json", default=str(ROOT / "results" / "result_plots.json"))
    args = ap.parse_args(argv)
    enable_x64()
    t0 = time.perf_counter()
    sample, dem, dsm, ste = solves(args.n, args.transits)
    st = dem.stats
    print(f"{sample.n_particles} particles, {sample.n_bonds} bonds; DEM: E = {dem.youngs_modulus:.4g} Pa, "
          f"strength {st['strength']:.4g} Pa at strain {st['strain_at_peak']:.4g}, broken bonds "
          f"{st['broken_tensile']} tension + {st['broken_shear']} shear, {dem.wall_time:.1f} s; DSM E = "
          f"{dsm.youngs_modulus:.4g} Pa ({dsm.wall_time:.2f} s); STE E = {ste.youngs_modulus:.4g} Pa "
          f"({ste.wall_time:.2f} s)")
    for path in figures(sample, dem, dsm, ste, args.out):
        print(f"wrote {path}")
    report = {"benchmark": "result_plots", "machine": machine_info(), "settings": vars(args) | {"out": str(args.out)},
              "particles": sample.n_particles, "bonds": sample.n_bonds, "total_time_s": time.perf_counter() - t0}
    for name, r in (("dem", dem), ("dsm", dsm), ("ste", ste)):
        report[name] = {"youngs_modulus": r.youngs_modulus, "wall_time": r.wall_time, "run_time": r.run_time}
    report["dem"].update({k: st[k] for k in ("strength", "strain_at_peak", "broken_tensile", "broken_shear",
                                             "stop_reason", "steps", "quasi_static")})
    print(f"wrote {write_json(args.json, report)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
