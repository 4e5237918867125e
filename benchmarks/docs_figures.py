"""The docs' opening figures that no benchmark draws: a first script's three solvers, a UCS run to failure and a
strength calibration.

* ``docs/figures/first_script.png`` (Getting started): the page's short example -- STE, DSM and DEM on a 500-particle
  box compressed by 0.2 % -- as a chart: each solver's Young's modulus and the wall time of its first and second
  call in one process.

* ``docs/figures/strength_ucs.png`` (the Strength page): a bonded cylinder (``--ucs-n`` particles, breakable bonds,
  sigma_c 4 MPa, tau_c 8 MPa) compressed to failure by the DEM (``UniaxialCompression.to_failure(strain=0.02)``):
  the stress–strain curve from the run's records (``record_to=``) with its peak (the UCS) and the line of the
  Young's modulus fitted over the scene's fit range, and the broken bonds (tensile, shear) on a second axis.
* ``docs/figures/calibration_strength.png`` (the Calibration page): Qu et al.'s simplified scheme
  (``calibrate.calibrate_strength``) from its first estimate to a UCS and a flexural strength made by the same DEM
  with sigma_c 4 MPa, tau_c 8 MPa (cylinder ``--ucs-n``, beam ``--tpb-n``): each strength's error per point and the
  path in (sigma_c, tau_c).

Drawn with Matplotlib from the results' own numbers. About 3 minutes on 2 shared cores::

    python benchmarks/docs_figures.py [--only first|strength|calibration] [--first-n 500] [--ucs-n 1500] [--calibration-ucs-n 250] [--tpb-n 300] [--out docs/figures]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(__file__))
from _common import enable_x64, machine_info, save_png  # noqa: E402

STRENGTHS = {"E": 1e9, "nu": 0.25, "tensile_strength": 4e6, "shear_strength": 8e6}


def _note() -> str:
    m = machine_info()
    return f"{m['platform']} ({m['cpu_count']} cores), jax {m['jax']}, {m['precision']}; python benchmarks/docs_figures.py"


def first_script_figure(n: int, out: str) -> str:
    """STE, DSM and DEM on an ``n``-particle box (the Getting started example), drawn to ``out``; returns the path."""
    import matplotlib.pyplot as plt

    import jaxbpm

    sample = jaxbpm.generate.box(n, mean_radius=1e-3, seed=0, materials={"E": 1e9, "nu": 0.25}).largest_cluster()
    scene = jaxbpm.scenes.UniaxialCompression(axis=2, strain=0.002)
    methods = ("ste", "dsm", "dem")
    first = {m: jaxbpm.solve(sample, scene, method=m) for m in methods}
    second = {m: jaxbpm.solve(sample, scene, method=m) for m in methods}
    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.4))
    names = [m.upper() for m in methods]
    bars = left.bar(names, [first[m].youngs_modulus / 1e6 for m in methods], color=["C2", "C0", "C3"])
    left.bar_label(bars, labels=[f"{first[m].youngs_modulus / 1e6:.1f}" for m in methods], padding=2, fontsize=8)
    left.set(ylabel="Young's modulus E [MPa]", title="the answer")
    for k, m in enumerate(methods):
        right.barh(k + 0.2, first[m].wall_time, height=0.4, color="0.7", label="1st call (compiles)" if k == 0 else None)
        right.barh(k - 0.2, second[m].wall_time, height=0.4, color=f"C{(2, 0, 3)[k]}",
                   label="2nd call" if k == 0 else None)
        right.text(second[m].wall_time * 1.15, k - 0.2, f"{second[m].wall_time:.3g} s", va="center", fontsize=8)
    right.set_yticks(range(3), names)
    right.set_xscale("log")
    right.set(xlabel="wall time of the call [s]", title="the wait")
    right.set_ylim(-0.6, 3.3)
    right.legend(fontsize=8, loc="upper left", ncols=2)
    fig.suptitle(f"jaxbpm.solve on {sample.n_particles} particles, {sample.n_bonds} bonds, 0.2 % compression",
                 fontsize=10)
    return save_png(fig, out, note=_note())


def ucs_figure(n: int, out: str) -> str:
    """The UCS run to failure of an ``n``-particle cylinder, drawn to ``out``; returns the path."""
    import matplotlib.pyplot as plt
    import numpy as np

    import jaxbpm
    from jaxbpm.dem.records import read_records
    from jaxbpm.scenes import UniaxialCompression

    rock = jaxbpm.generate.cylinder(n, seed=0, packing_fraction=0.52, materials=STRENGTHS).largest_cluster()
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        res = jaxbpm.solve(rock, UniaxialCompression.to_failure(strain=0.02), "dem",
                           record_to=os.path.join(tmp, "ucs.h5"))
        wall = time.perf_counter() - t
        rec, _ = read_records(os.path.join(tmp, "ucs.h5"))
    strain = 100 * np.asarray(rec["displacement"]) / res.gauge_length
    stress = np.asarray(rec["force"]) / res.area / 1e6
    broken = np.asarray(rec["broken"])
    peak = int(np.argmax(stress))
    fig, ax = plt.subplots(figsize=(7, 4.2))
    ax.plot(strain, stress, color="k", lw=1.5, label="stress (DEM)")
    ax.plot(strain[peak], stress[peak], "o", color="C3", ms=8,
            label=f"peak: UCS {stress[peak]:.2f} MPa at {strain[peak]:.2f} %")
    line = np.linspace(0, strain[peak], 2)
    ax.plot(line, res.youngs_modulus * line / 100 / 1e6, "--", color="C0",
            label=f"E = {res.youngs_modulus / 1e6:.0f} MPa (fit range)")
    ax.set(xlabel="axial strain [%]", ylabel="axial stress [MPa]", ylim=(0, 1.25 * stress[peak]))
    twin = ax.twinx()
    twin.plot(strain, broken[:, 0], color="C1", lw=1, label="broken bonds, tension")
    twin.plot(strain, broken[:, 1], color="C2", lw=1, label="broken bonds, shear")
    twin.set_ylabel("broken bonds (cumulative)")
    handles = ax.get_legend_handles_labels()[0] + twin.get_legend_handles_labels()[0]
    ax.legend(handles=handles, loc="upper left", fontsize=8)
    ax.set_title(f"UCS to failure: {rock.n_particles} particles, {rock.n_bonds} bonds, sigma_c 4 MPa, tau_c 8 MPa "
                 f"({wall:.0f} s)", fontsize=10)
    print(f"UCS {stress[peak]:.4g} MPa, E {res.youngs_modulus:.4g} Pa, broken {broken[-1].tolist()}, "
          f"stop {res.stats.get('stop_reason')}, {wall:.1f} s", flush=True)
    return save_png(fig, out, note=_note())


def calibration_figure(ucs_n: int, tpb_n: int, out: str) -> str:
    """Qu et al.'s simplified strength calibration on a cylinder and a beam, drawn to ``out``; returns the path."""
    import matplotlib.pyplot as plt
    import numpy as np

    import jaxbpm
    from jaxbpm import calibrate as cal
    from jaxbpm.physics.model import default_params
    from jaxbpm.scenes import ThreePointBending, UniaxialCompression

    cyl = jaxbpm.generate.cylinder(ucs_n, seed=0, materials=STRENGTHS).largest_cluster()
    beam = jaxbpm.generate.beam(tpb_n, seed=1, packing_fraction=0.52, materials=STRENGTHS).largest_cluster()
    ucs_scene, tpb_scene = UniaxialCompression.to_failure(strain=0.02), ThreePointBending(strain=0.1)
    true = {"bond_tensile_strength": np.array([4e6]), "bond_shear_strength": np.array([8e6])}
    ucs = jaxbpm.solve(cyl, ucs_scene, "dem", params={**default_params(cyl), **true}, transits=30).stats["strength"]
    flex = jaxbpm.solve(beam, tpb_scene, "dem", params={**default_params(beam), **true}, transits=30).stats["strength"]
    res = cal.calibrate_strength(cyl, beam, ucs=float(ucs), flexural=float(flex), scheme="simplified",
                                 ucs_scene=ucs_scene, tpb_scene=tpb_scene, tol=0.05, learning_rate=0.2, fd_step=0.2,
                                 max_iterations=6, solve_options={"transits": 30})
    hist = cal.strength_table(res)
    print(cal.format_strength_table(hist), flush=True)
    point = [h["iteration"] for h in hist]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    axes[0].axhspan(-5, 5, color="C2", alpha=0.15, label="±5 % (tol)")
    axes[0].plot(point, [100 * h["ucs_error"] for h in hist], "o-", label="UCS")
    axes[0].plot(point, [100 * h["flexural_error"] for h in hist], "s-", label="flexural strength")
    axes[0].axhline(0, color="k", lw=0.7)
    axes[0].set_xticks(point, [f"{h['iteration']}\n{h['kind']}" for h in hist])
    axes[0].set(xlabel="point (Qu et al.'s two estimates, then the scheme's steps)", ylabel="error [%]",
                title="strength errors per point")
    axes[0].legend(fontsize=8)
    axes[1].plot([h["sigma_c"] / 1e6 for h in hist], [h["tau_c"] / 1e6 for h in hist], "o-", color="C0")
    for h in hist:
        axes[1].annotate(str(h["iteration"]), (h["sigma_c"] / 1e6, h["tau_c"] / 1e6), textcoords="offset points",
                         xytext=(5, 4), fontsize=8)
    axes[1].plot([4.0], [8.0], "k*", ms=12, label="strengths behind the targets")
    axes[1].set(xlabel="bond tensile strength σc [MPa]", ylabel="bond shear strength τc [MPa]",
                title="path of (σc, τc)")
    axes[1].legend(fontsize=8)
    fig.suptitle(f"Qu et al.'s simplified scheme: cylinder {cyl.n_particles}, beam {beam.n_particles} particles, "
                 f"{res.info['parameter_sets']} parameter sets, {res.wall_time:.0f} s", fontsize=10)
    return save_png(fig, out, note=_note())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first-n", type=int, default=500, dest="first_n")
    ap.add_argument("--ucs-n", type=int, default=1500, dest="ucs_n")
    ap.add_argument("--calibration-ucs-n", type=int, default=250, dest="cal_ucs_n")
    ap.add_argument("--tpb-n", type=int, default=300, dest="tpb_n")
    ap.add_argument("--out", default=os.path.join("docs", "figures"))
    ap.add_argument("--only", choices=("first", "strength", "calibration"), default=None)
    args = ap.parse_args(argv)
    enable_x64()
    written = []
    if args.only in (None, "first"):
        written.append(first_script_figure(args.first_n, os.path.join(args.out, "first_script.png")))
    if args.only in (None, "strength"):
        written.append(ucs_figure(args.ucs_n, os.path.join(args.out, "strength_ucs.png")))
    if args.only in (None, "calibration"):
        written.append(calibration_figure(args.cal_ucs_n, args.tpb_n,
                                          os.path.join(args.out, "calibration_strength.png")))
    for path in written:
        print(f"wrote {path}")
    return written


if __name__ == "__main__":
    main()
