#!/usr/bin/env python
"""The STE's two boundary forms against the DSM: a clamped simple-cubic lattice and random packings.

Usage::

    python benchmarks/ste_boundary.py                 # SC lattice 10x10x20, boxes of 1k and 3k, a porous cylinder
    python benchmarks/ste_boundary.py --quick         # SC lattice 4x4x8 and the 1k box

Forms (``jaxbpm.solve(..., method="ste", ...)``, uniaxial compression along z, 0.2 % strain, clamped end layers):

* ``clamped`` (the default, ``boundary="clamped"``): the scene's clamped particles follow the affine field and are
  left out of the averages; particles within one diameter of the faces parallel to the load too.
* ``clamped, surface_depth=0``: every non-clamped, non-singular particle averaged.
* ``free`` (``boundary="free"``, the paper's form): every particle relaxes; particles within one diameter of any
  face left out of the averages.
* ``free, surface_depth=0``: every non-singular particle averaged (as Jarolin & Dosta computed it).
* ``clamped, dofs=6`` and ``free, dofs=6``: the same with rotations.

References: the linear DSM with 3 DOF per particle (the 3-DOF STE's own model) and with 6 (the DEM's model; the
6-DOF STE's own); on the lattice the closed form K = n_x n_y k_n / (n_z - 1) (n_x n_y chains of n_z - 1 bonds,
the end layers clamped through ``fixed``/``driven`` masks, l = (n_z - 1) d, A = n_x n_y d^2). Errors are K / ref -
1. JSON to ``results/ste_boundary.json``.
"""

from __future__ import annotations

import argparse
import sys
import time

from _common import enable_x64, machine_info, table, write_json

FORMS = {"clamped": {}, "clamped, surface_depth=0": {"surface_depth": 0.0}, "free": {"boundary": "free"},
         "free, surface_depth=0": {"boundary": "free", "surface_depth": 0.0}, "clamped, dofs=6": {"dofs": 6},
         "free, dofs=6": {"boundary": "free", "dofs": 6}}


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def clamped_lattice(cells, radius=1e-3):
    """``(sample, scene, K exact)``: an SC lattice with its end layers clamped through masks."""
    import numpy as np

    import jaxbpm
    from jaxbpm import ste
    from jaxbpm.physics.model import default_params
    from jaxbpm.scenes import UniaxialCompression

    nx, ny, nz = cells
    d = 2 * radius
    s = jaxbpm.generate.lattice("sc", cells, radius, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    z = np.asarray(s.positions)[:, 2]
    scene = UniaxialCompression(strain=0.002, fixed=np.isclose(z, z.min()), driven=np.isclose(z, z.max()),
                                gauge_length=(nz - 1) * d, area=nx * ny * d**2)
    kn = float(ste.estimator(s).model.stiffness(default_params(s)).kn[0])
    return s, scene, nx * ny * kn / (nz - 1)


def samples(quick: bool):
    """``[(name, sample, scene, K exact or None)]``."""
    import jaxbpm
    from jaxbpm.scenes import UniaxialCompression

    mat = {"E": 1e9, "nu": 0.25}
    cells = (4, 4, 8) if quick else (10, 10, 20)
    s, scene, exact = clamped_lattice(cells)
    out = [(f"SC lattice {'x'.join(map(str, cells))}", s, scene, exact)]
    box = jaxbpm.generate.box(1000, seed=3, mean_radius=1e-3, packing_fraction=0.58, materials=mat)
    out.append(("random box 1k", box.largest_cluster(), UniaxialCompression(strain=0.002), None))
    if not quick:
        box = jaxbpm.generate.box(3000, seed=0, mean_radius=1e-3, packing_fraction=0.58, materials=mat)
        out.append(("random box 3k", box.largest_cluster(), UniaxialCompression(strain=0.002), None))
        cyl = jaxbpm.generate.cylinder(2000, seed=0, mean_radius=1e-3, packing_fraction=0.5, materials=mat)
        out.append(("porous cylinder 2k", cyl.largest_cluster(), UniaxialCompression(strain=0.002), None))
    return out


def measure(name, sample, scene, exact):
    """The rows of one sample: every form's K and its errors against the references."""
    import jaxbpm

    dsm = {d: jaxbpm.solve(sample, scene, method="dsm", dofs=d).stiffness for d in (3, 6)}
    log(f"{name}: {sample.n_particles} particles, DSM 3 DOF {dsm[3]:.6g}, 6 DOF {dsm[6]:.6g} N/m"
        + (f", exact {exact:.6g}" if exact else ""))
    rows = []
    for form, opts in FORMS.items():
        r = jaxbpm.solve(sample, scene, method="ste", **opts)
        row = {"sample": name, "form": form, "particles": sample.n_particles, "K": r.stiffness,
               "vs_dsm3": r.stiffness / dsm[3] - 1, "vs_dsm6": r.stiffness / dsm[6] - 1,
               "vs_exact": None if exact is None else r.stiffness / exact - 1, "clamped": r.stats["clamped"],
               "surface": r.stats["surface"], "boundary": r.stats["boundary"]}
        rows.append(row)
        log(f"  {form:28s} K {r.stiffness:.6g}  vs DSM3 {100 * row['vs_dsm3']:+.3g} %  vs DSM6 "
            f"{100 * row['vs_dsm6']:+.3g} %")
    return rows, {"sample": name, "dsm3": dsm[3], "dsm6": dsm[6], "exact": exact}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="SC lattice 4x4x8 and the 1k box")
    ap.add_argument("--out", default="results/ste_boundary.json")
    args = ap.parse_args(argv)
    enable_x64()
    t0 = time.perf_counter()
    rows, refs = [], []
    for name, sample, scene, exact in samples(args.quick):
        r, ref = measure(name, sample, scene, exact)
        rows += r
        refs.append(ref)
    shown = [{**r, **{k: (f"{100 * r[k]:+.3g} %" if r[k] is not None else "") for k in
                      ("vs_dsm3", "vs_dsm6", "vs_exact")}} for r in rows]
    table(shown, ["sample", "form", "vs_exact", "vs_dsm3", "vs_dsm6", "clamped", "surface"])
    out = {"benchmark": "ste_boundary", "machine": machine_info(), "settings": vars(args), "references": refs,
           "rows": rows, "total_time_s": time.perf_counter() - t0,
           "notes": "STE, Eq. 32, uniaxial compression along z at 0.2 %; errors K / reference - 1; dsm3 / dsm6: the "
                    "linear DSM with 3 / 6 DOF per particle"}
    print(f"wrote {write_json(args.out, out)}")


if __name__ == "__main__":
    main()
