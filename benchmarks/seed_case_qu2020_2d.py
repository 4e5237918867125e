"""Qu et al. 2020's SiC ceramic in 2D, as the paper ran it: discs under PFC's linear parallel-bond model, a
three-point-bending beam of 22,507 discs and a uniaxial-compression specimen of 66,743 discs (Section 4, Tables 3-6).

Parameters (Table 3, PFC2D names through :mod:`jaxbpm.interop.pfc`): ``emod = pb_emod = 211 GPa``, ``kratio =
pb_kratio = 1.21`` (grains and bonds), ``pb_rmul = 1``, ``fric = 0.7``, density 2600 kg/m^3, radii uniform in
4.5-6.75 um, bonds between discs closer than the bond gap 0.2 um; unit thickness (PFC2D's). The paper does not give
the specimens' dimensions, the porosity or the supports; the choices (see ``docs/two-dimensions.md``, "Seed case"):

* UCS: a rectangle of height 2 x width (PFC2D's usual, Potyondy & Cundall 2004), compressed along y between clamped
  end layers (2D walls are not available);
* TPBT: a beam of the proportions of ASTM C1161's configuration A for advanced ceramics (25 x 3 mm, span 20 mm:
  length 8.33 x depth, span 80 % of the length), on two roller discs of 5 mean radii and pressed by a third at
  mid-span (``ThreePointBending(rollers=True)``: the scene adds them); the rollers touch the beam through linear
  contacts only, so the supports do not hold the beam's ends horizontally as clamped support layers would;
* packing fraction: ``generate.disc_packing``'s default (about 0.82);
* loading: the UCS over ``--transits`` (30) elastic-wave transits, the beam ``--beam-slowdown`` (9) times slower
  (its strength still falls by 40 % from 30 to 270 transits of the span).

Then (a) the paper's own parameter sets (Table 4 rows 0 and 6, Table 5 row 3) forward over several packings, and (b)
``jaxbpm.calibrate.calibrate_strength`` with the original and the simplified scheme from Eq. 14's starting point,
printed beside Tables 4 and 5, and jaxbpm's own scheme (``--schemes lab``: the strength stage of
``jaxbpm.calibrate.lab``, the same two estimates, then Gauss-Newton steps).

    python benchmarks/seed_case_qu2020.py --2d --quick          # ~2,250 + ~6,700 discs
    python benchmarks/seed_case_qu2020.py --2d                  # 22,507 + 66,743 discs
    python benchmarks/seed_case_qu2020.py --2d --parts paper-beam --seeds 0   # one timed 22,507-disc beam run
    python benchmarks/seed_case_qu2020.py --2d --quick --parts ucs-rate --seeds 0   # the UCS against the rate
"""

from __future__ import annotations

import argparse
import dataclasses
import time

R_MEAN, SPREAD, BOND_GAP = 5.625e-6, 0.2, 2e-7  # 4.5-6.75 um uniform; Table 3's bond gap [m]
PAPER_COUNTS = {"tpb": 22507, "ucs": 66743}
BEAM_ASPECT, SPAN_FRACTION, UCS_ASPECT = (25.0 / 3.0, 1.0), 0.8, (1.0, 2.0)
ROLLER = 5.0  # roller radius, mean disc radii
FRICTION = 0.7
TARGETS = {"flexural": 0.78e9, "ucs": 2.0e9}
# Qu et al. 2020: (pb_ten, pb_coh) -> (flexural, UCS) [Pa]
TABLE4 = [(780000000, 2000000000, 483187287, 1412539673), (1259139087, 2831778870, 630918442, 1901278790),
          (1259291059, 2831389198, 808304937, 1782465166), (1259329214, 2831291492, 763528681, 1925063036),
          (1259332906, 2831286456, 605471455, 2023346510), (1259247913, 2831572616, 895699459, 1990474860),
          (1259193451, 2831687578, 758825095, 1996876485)]
TABLE5 = [(780000000, 2000000000, 483187287, 1412539673), (1259139087, 2831778870, 630918442, 1901278790),
          (1251371869, 2811779011, 631324376, 1928287161), (1256778352, 2826577761, 791682779, 1939762947),
          (1251833604, 2848432059, 702274563, 1831369247), (1255654758, 2861930486, 820511252, 2052768684),
          (1258923303, 2873820570, 772275118, 1825236495)]
PAPER_SETS = {"Table 4 row 0": TABLE4[0], "Table 4 row 6": TABLE4[6], "Table 5 row 3": TABLE5[3]}
QU2020_MODELS = {"original": 19, "simplified": 4}


def pfc(pb_ten: float = 0.78e9, pb_coh: float = 2e9, fric: float = FRICTION) -> dict:
    """Table 3's linear parallel-bond properties (PFC2D names) with the bond strengths given."""
    return {"emod": 211e9, "kratio": 1.21, "pb_emod": 211e9, "pb_kratio": 1.21, "pb_ten": pb_ten, "pb_coh": pb_coh,
            "fric": fric}


def _packing(n: int, shape: str, aspect, seed: int):
    from jaxbpm.generate import disc_packing
    from jaxbpm.interop.pfc import from_pfc

    p = from_pfc(pfc())
    materials = {"E": float(p["bond_E"][0]), "nu": float(p["bond_nu"][0]),
                 "tensile_strength": float(p["bond_tensile_strength"][0]),
                 "shear_strength": float(p["bond_shear_strength"][0])}
    return disc_packing(n, shape, aspect=aspect, mean_radius=R_MEAN, radius_spread=SPREAD, bond_gap=BOND_GAP / R_MEAN,
                        bond_radius_ratio=1.0, seed=seed, materials=materials,
                        particle_material={"density": 2600.0, "E": 211e9, "nu": 0.2, "friction": FRICTION}
                        ).largest_cluster()


def contact_law():
    """Table 3's linear contacts between discs: PFC's ``emod``, ``kratio`` and ``fric``."""
    from jaxbpm.physics.linear import LinearLaw

    return LinearLaw(emod=211e9, kratio=1.21, friction=FRICTION)


def ucs_specimen(n: int, seed: int = 0):
    """The UCS specimen of about ``n`` discs (a rectangle, height 2 x width) and its scene.

    Returns:
      ``(sample, scene)``.
    """
    from jaxbpm.scenes import UniaxialCompression

    return _packing(n, "rectangle", UCS_ASPECT, seed), UniaxialCompression.to_failure(axis=1, contact_law=contact_law())


def _bending_class():
    from jaxbpm.scenes import ThreePointBending

    @dataclasses.dataclass(frozen=True)
    class SlowBending(ThreePointBending):
        """Three-point bending whose loading time counts ``transit_scale`` transits along the span per transit asked
        for (the beam's strength converges at slower loading than the UCS's)."""

        transit_scale: float = 1.0

        def transit_length(self, sample):
            """The span times ``transit_scale``."""
            return float(self.dimensions(sample)[0]) * float(self.transit_scale)

    return SlowBending


def beam_specimen(n: int, seed: int = 0, roller: float = ROLLER):
    """The TPBT beam of about ``n`` discs and its scene: on two roller discs, pressed by a third.

    The scene adds the rollers (``ThreePointBending(rollers=True)``, radius ``roller`` mean radii), each touching the
    beam (its lowest disc under each support point, its highest at mid-span) and carrying the load through the linear
    contacts alone; ``jaxbpm.solve`` adds them to the beam (the result's ``stats["added_particles"]`` is 3).

    Returns:
      ``(sample, scene)``: the beam alone, and a :class:`~jaxbpm.scenes.ThreePointBending` with ``rollers=True``
      (span 80 % of the beam's length).
    """
    import numpy as np

    s = _packing(n, "beam", BEAM_ASPECT, seed)
    x, rad = np.asarray(s.positions), np.asarray(s.radii)
    lo, hi = (x - rad[:, None]).min(axis=0), (x + rad[:, None]).max(axis=0)
    length, height = hi - lo
    rr = roller * R_MEAN
    # the punch's travel: h^2 / (10 (h + 4 r_roller)), the loading speed of the runs in docs/two-dimensions.md
    strain = 0.1 * height / (height + 4 * rr)
    scene = _bending_class()(axis=1, span_axis=0, span=float(SPAN_FRACTION * length), rollers=True,
                             roller_radius=float(rr), contact_law=contact_law(), breakage=True, strain=strain)
    return s, scene


def params_for(sample, pb_ten: float, pb_coh: float) -> dict:
    """jaxbpm's params of ``sample`` for PFC's Table 3 with the bond strengths given."""
    from jaxbpm.interop.pfc import from_pfc

    return from_pfc(pfc(pb_ten, pb_coh), sample=sample)


def strength(sample, scene, pb_ten: float, pb_coh: float, transits: float) -> tuple[float, float, dict]:
    """One failure run: ``(strength [Pa], wall [s], stats)``."""
    import warnings

    import jaxbpm

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # PFC's L = R1 + R2 against the bonds' gaps: stated in the docs
        r = jaxbpm.solve(sample, scene, "dem", params=params_for(sample, pb_ten, pb_coh), transits=transits,
                         throw=False)
    stats = {"status": r.status, "steps": int(r.stats.get("steps", 0)), "broken_tensile":
             int(r.stats.get("broken_tensile", 0)), "broken_shear": int(r.stats.get("broken_shear", 0))}
    return float(r.stats.get("strength", float("nan"))), time.perf_counter() - t0, stats


def _forward(args, out: dict) -> None:
    """(a) the paper's parameter sets, forward, over ``args.seeds`` packings."""
    import numpy as np

    from _common import table

    rows = []
    for seed in args.seeds:
        t0 = time.perf_counter()
        (beam, tpb), (cyl, ucs) = beam_specimen(args.tpb_n, seed), ucs_specimen(args.ucs_n, seed)
        tpb = dataclasses.replace(tpb, transit_scale=args.beam_slowdown)
        span, _, height = tpb.dimensions(beam)
        print(f"seed {seed}: beam {beam.n_particles} discs / {beam.n_bonds} bonds "
              f"({span / SPAN_FRACTION * 1e3:.3f} x {height * 1e3:.3f} mm, span {span * 1e3:.3f} mm), UCS "
              f"{cyl.n_particles} / {cyl.n_bonds} ({time.perf_counter() - t0:.0f} s to generate)", flush=True)
        for name, (ten, coh, f_paper, u_paper) in PAPER_SETS.items():
            f, wf, sf = strength(beam, tpb, ten, coh, args.transits)
            u, wu, su = strength(cyl, ucs, ten, coh, args.transits)
            rows.append({"set": name, "seed": seed, "flexural": f, "flexural_paper": f_paper,
                         "flexural_vs_paper": f / f_paper - 1, "ucs": u, "ucs_paper": u_paper,
                         "ucs_vs_paper": u / u_paper - 1, "wall_tpb_s": wf, "wall_ucs_s": wu, "tpb": sf, "ucs_run": su})
            print(f"  {name}: flexural {f / 1e9:.3f} GPa (paper {f_paper / 1e9:.3f}, "
                  f"{100 * (f / f_paper - 1):+.1f} %), "
                  f"UCS {u / 1e9:.3f} GPa (paper {u_paper / 1e9:.3f}, {100 * (u / u_paper - 1):+.1f} %); "
                  f"{wf:.0f} s + {wu:.0f} s", flush=True)
    summary = []
    for name, (_, _, f_paper, u_paper) in PAPER_SETS.items():
        f = np.array([r["flexural"] for r in rows if r["set"] == name])
        u = np.array([r["ucs"] for r in rows if r["set"] == name])
        summary.append({"set": name, "flexural_mean": f.mean(), "flexural_cv": f.std(ddof=1) / f.mean() if len(f) > 1
                        else 0.0, "flexural_paper": f_paper, "flexural_vs_paper": f.mean() / f_paper - 1,
                        "ucs_mean": u.mean(), "ucs_cv": u.std(ddof=1) / u.mean() if len(u) > 1 else 0.0,
                        "ucs_paper": u_paper, "ucs_vs_paper": u.mean() / u_paper - 1, "seeds": len(f)})
    table(summary, ["set", "seeds", "flexural_mean", "flexural_cv", "flexural_paper", "flexural_vs_paper",
                    "ucs_mean", "ucs_cv", "ucs_paper", "ucs_vs_paper"])
    out["forward"], out["forward_summary"] = rows, summary


def _calibrate(args, out: dict) -> None:
    """(b) the original and the simplified scheme from Eq. 14's starting point, beside Tables 4 and 5."""
    from jaxbpm.calibrate.lab import lab
    from jaxbpm.calibrate.strength import calibrate_strength, format_strength_table, strength_table

    (beam, tpb), (cyl, ucs) = beam_specimen(args.tpb_n, args.seeds[0]), ucs_specimen(args.ucs_n, args.seeds[0])
    tpb = dataclasses.replace(tpb, transit_scale=args.beam_slowdown)
    out["calibration"] = {}
    for scheme in args.schemes:
        t0 = time.perf_counter()
        if scheme == "lab":  # jaxbpm's own: the strength stage of calibrate.lab (Gauss-Newton steps)
            res = lab({"ucs": cyl, "flexural": beam}, TARGETS, scenes={"ucs": ucs, "flexural": tpb}, tol=args.tol,
                      max_iterations=args.max_iterations[scheme], solve_options={"transits": args.transits},
                      progress=True).stages["strength"]
            res.info.update(targets={"ucs": TARGETS["ucs"], "tpb": TARGETS["flexural"]},
                            parameter_sets=res.evaluations // 2)
        else:
            res = calibrate_strength(cyl, beam, ucs=TARGETS["ucs"], flexural=TARGETS["flexural"], scheme=scheme,
                                     ucs_scene=ucs, tpb_scene=tpb, learning_rate=args.learning_rate, tol=args.tol,
                                     max_iterations=args.max_iterations[scheme],
                                     solve_options={"transits": args.transits}, progress=True)
        rows = strength_table(res)
        paper = TABLE4 if scheme in ("original", "lab") else TABLE5
        print(f"\n{scheme} scheme (jaxbpm, {cyl.n_particles} + {beam.n_particles} discs; "
              f"{time.perf_counter() - t0:.0f} s):\n{format_strength_table(rows)}")
        print(f"Qu et al. 2020, {'Table 4' if paper is TABLE4 else 'Table 5'}:")
        for i, (ten, coh, f, u) in enumerate(paper):
            print(f"{i:>3} {ten:>13.6g} {coh:>13.6g} {f:>14.6g} {u:>13.6g} {100 * (f / 0.78e9 - 1):>+7.1f}% "
                  f"{100 * (u / 2e9 - 1):>+7.1f}%")
        out["calibration"][scheme] = {"rows": rows, "converged": bool(res.converged), "values": res.values,
                                      "parameter_sets": res.info["parameter_sets"], "notes": list(res.notes),
                                      "wall_s": time.perf_counter() - t0,
                                      "qu2020_models": QU2020_MODELS.get(scheme, QU2020_MODELS["original"])}


def _ucs_rate(args, out: dict) -> None:
    """The UCS of one packing at Table 4 row 0 against the loading time (``--rates``, in elastic-wave transits)."""
    cyl, ucs = ucs_specimen(args.ucs_n, args.seeds[0])
    ten, coh, _, u_paper = TABLE4[0]
    rows = []
    for transits in args.rates:
        u, wall, stats = strength(cyl, ucs, ten, coh, transits)
        rows.append({"transits": transits, "ucs": u, "ucs_vs_paper": u / u_paper - 1, "wall_s": wall, **stats})
        print(f"UCS at {transits:g} transits: {u / 1e9:.4f} GPa (paper {u_paper / 1e9:.3f}, "
              f"{100 * (u / u_paper - 1):+.1f} %), {stats['steps']} steps, {wall:.0f} s, {stats}", flush=True)
    out["ucs_rate"] = {"discs": cyl.n_particles, "bonds": cyl.n_bonds, "seed": args.seeds[0], "rows": rows}


def _paper_beam(args, out: dict) -> None:
    """One forward failure run of the paper-size beam (Table 4 row 0), timed."""
    t0 = time.perf_counter()
    beam, tpb = beam_specimen(PAPER_COUNTS["tpb"], args.seeds[0])
    gen = time.perf_counter() - t0
    tpb = dataclasses.replace(tpb, transit_scale=args.beam_slowdown)
    f, wall, stats = strength(beam, tpb, *TABLE4[0][:2], args.transits)
    print(f"paper-size beam: {beam.n_particles} discs, {beam.n_bonds} bonds, generated in {gen:.0f} s; "
          f"flexural {f / 1e9:.3f} GPa (paper {TABLE4[0][2] / 1e9:.3f}) in {wall:.0f} s, {stats}", flush=True)
    out["paper_beam"] = {"discs": beam.n_particles, "bonds": beam.n_bonds, "generate_s": gen,
                         "flexural": f, "wall_s": wall, **stats}


def main(argv=None):
    """``seed_case_qu2020.py --2d``: see the module docstring."""
    import os
    import sys

    sys.path.insert(0, os.path.dirname(__file__))
    from _common import enable_x64, machine_info, write_json

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--2d", action="store_true", dest="two_d", help="(the 2D case; accepted for the 3D script's "
                    "command line)")
    ap.add_argument("--quick", action="store_true", help="a tenth of the paper's sizes")
    ap.add_argument("--ucs-n", type=int, default=PAPER_COUNTS["ucs"], dest="ucs_n")
    ap.add_argument("--tpb-n", type=int, default=PAPER_COUNTS["tpb"], dest="tpb_n")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--transits", type=float, default=30.0, help="the UCS's loading time in elastic-wave transits")
    ap.add_argument("--beam-slowdown", type=float, default=9.0, dest="beam_slowdown",
                    help="the beam is loaded this many times slower (its strength still moves at 30 transits)")
    ap.add_argument("--learning-rate", type=float, default=0.01, dest="learning_rate", help="Adam's (the paper's)")
    ap.add_argument("--tol", type=float, default=0.05)
    ap.add_argument("--max-iterations", type=int, default=None, dest="budget",
                    help="every scheme's max_iterations (default: original 3, simplified 5, lab 6)")
    ap.add_argument("--schemes", nargs="*", default=["original", "simplified", "lab"],
                    choices=["original", "simplified", "lab"], help="Qu et al.'s two schemes, and jaxbpm's own (the "
                    "strength stage of calibrate.lab: Gauss-Newton steps)")
    ap.add_argument("--parts", nargs="+", default=["forward", "calibrate"],
                    choices=["forward", "calibrate", "paper-beam", "ucs-rate"])
    ap.add_argument("--rates", type=float, nargs="+", default=[30.0, 90.0, 270.0, 810.0],
                    help="the loading times of --parts ucs-rate, in elastic-wave transits")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    if args.quick:
        args.ucs_n, args.tpb_n = PAPER_COUNTS["ucs"] // 10, PAPER_COUNTS["tpb"] // 10
    args.max_iterations = {"original": 3, "simplified": 5, "lab": 6}
    if args.budget is not None:
        args.max_iterations = dict.fromkeys(args.max_iterations, args.budget)
    out_path = args.out or f"results/seed_case_qu2020_2d{'_quick' if args.quick else ''}_{'_'.join(args.parts)}.json"
    enable_x64()
    t0 = time.perf_counter()
    out = {"benchmark": "seed_case_qu2020_2d", "machine": machine_info(), "settings": vars(args), "targets": TARGETS,
           "qu2020": {"table4": TABLE4, "table5": TABLE5, "models": QU2020_MODELS}}
    for part in args.parts:
        parts = {"forward": _forward, "calibrate": _calibrate, "paper-beam": _paper_beam, "ucs-rate": _ucs_rate}
        parts[part](args, out)
    out["total_time_s"] = time.perf_counter() - t0
    write_json(out_path, out)
    print(f"wrote {out_path}")


if __name__ == "__main__":
    main()
