#!/usr/bin/env python
"""jaxbpm vs LAMMPS in two dimensions: the same bonded disc sample, the same compression, one thread each.

Usage::

    python benchmarks/vs_lammps_2d.py                 # 10 000 discs, bonds only, both codes
    python benchmarks/vs_lammps_2d.py --quick         # 2000 discs
    python benchmarks/vs_lammps_2d.py --scene beam    # a 20 000-disc beam bent to failure, jaxbpm alone

The ``bonds`` scene (default)
-----------------------------
* Sample: ``generate.disc_packing(n, "rectangle", aspect=(1, 2))`` (polydisperse discs, radius spread 0.25, mean
  radius 1 mm, bonded where the gap is below 0.05 mean radii, r_b = 0.5 min(r_i, r_j)), thickness 1 m; bonds
  E = 1 GPa, nu = 0.25, no strengths (no breakage); density 2500 kg/m^3.
* Written for LAMMPS by jaxbpm's own writer (:func:`jaxbpm.interop.formats.write_lammps_data`, ``dimension 2``:
  z = 0) with the ``bpm/rotational`` coefficients of the ``2 r_b x t`` rectangle
  (:func:`jaxbpm.interop.lammps.lammps_coefficients`; one bond type per distinct row, numbered by first appearance).
  LAMMPS: ``units si``, ``dimension 2``, ``boundary f f p``, ``atom_style bpm/sphere``, ``special_bonds lj 0 1 1
  coul 1 1 1``, no pair style (bonded pairs feel their bond only, as jaxbpm's ``contacts=False``),
  ``bond_style bpm/rotational break no smooth no`` (no bond damping), ``set group all density/disc rho t`` (disc
  masses rho pi R^2 t), the mobile discs ``fix nve/bpm/sphere disc`` (moment of inertia m R^2 / 2, as jaxbpm's
  discs) + ``fix damping/cundall 0.7 0.7`` (jaxbpm's local damping) + ``fix enforce2d``, the bottom layer not
  integrated, the top layer ``fix move linear`` down.
* Loading: jaxbpm's ``UniaxialCompression(axis=1, strain=2e-3, boundary="layers")`` run by the DEM for
  ``--transits`` elastic-wave transit times; its time step (0.5 x its critical step), speed and number of steps are
  given to LAMMPS. Both record the end reactions; K is fitted by ``scene.fit_stiffness`` over the same 25-100 % of
  the target displacement for both, E = K l / A (l, A from ``scene.geometry``: A = width x thickness).
* Agreement: E of both, and the stress at the final strain, as ratios jaxbpm / LAMMPS. The 2D bond laws are the
  same to first order (LAMMPS's ``bpm/rotational`` in the plane: stretch, shear at the midpoint, bending about z);
  they differ at second order only, as in 3D (see ``benchmarks/vs_lammps.py``).
* Throughput: bond-steps/s (the sample's bonds) of the one run of each code: jaxbpm's median over its jitted chunks
  (compilation excluded) and LAMMPS's median over ~20 ``run M pre no post no`` segments after a ``run 0`` setup; the
  CPU-time rates (steps over the process's CPU seconds) beside them, the least noisy on a shared machine. Both
  pinned to the same core, one after the other (jaxbpm first, then LAMMPS in a subprocess of this script, since
  its MPI library must be on ``LD_LIBRARY_PATH`` when the process starts); jaxbpm with ``XLA_FLAGS=
  --xla_cpu_multi_thread_eigen=false``, LAMMPS serial with ``OMP_NUM_THREADS=1``.
  Each code's run is timed once (no repetition, no best-of): the wall time of the call beside its setup, compile
  and kernel (steps) time. jaxbpm runs twice, with its defaults (a bonds-only run is padded to its size class, so
  that samples of about the same size share one compiled program: about 13 % more bonds and discs computed) and with
  ``pad=False`` (the sample's own arrays), two programs timed once each.

LAMMPS's contacts are not compared: jaxbpm's linear contact law between discs has ``k_n = E* 2 min(R1, R2) t /
(R1 + R2)``, which varies from pair to pair in a polydisperse packing, while ``pair_style granular``'s ``hooke``
model (and ``bpm/spring``) takes one ``k_n`` per pair of atom types: the two would run different physics.

The ``beam`` scene
------------------
A three-point-bending beam of ``--beam-n`` discs (``generate.disc_packing(n, "beam")``, aspect 4:1,
``largest_cluster()``), bonds E = 1 GPa, nu = 0.25, sigma_c = 4 MPa, tau_c = 8 MPa (PFC's rule, jaxbpm's
``"separate"``), ``ThreePointBending(axis=1, span_axis=0, contact_law="linear")`` with supports and punch 4 mean
radii wide and 2 deep (the defaults, one diameter by one radius, can miss every disc of a random packing), the DEM's
defaults otherwise (40 transits, damping 0.7, the stop after the peak at 70 % of it). Reported: steps (and those
planned), the time step, the wall and CPU time of ``solve`` beside its setup, compile and run time, steps/s by wall
clock and by CPU time, the stop reason, the peak force, the flexural strength and the broken bonds.

JSON (atomic, ``benchmarks/_common.write_json``): ``results/vs_lammps_2d[_quick].json``, ``results/beam_2d.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one thread, before numpy/jax
    os.environ[_var] = "1"

import numpy as np  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import vs_lammps as V  # noqa: E402  (pinning, XLA flags, LAMMPS discovery and timed segments)

BOND_MATS = {"E": 1e9, "nu": 0.25}
BEAM_MATS = {"E": 1e9, "nu": 0.25, "tensile_strength": 4e6, "shear_strength": 8e6}
DENSITY = 2500.0

_SETUP_2D = """
units si
dimension 2
boundary f f p
atom_style bpm/sphere
atom_modify map array
comm_modify vel yes
special_bonds lj 0 1 1 coul 1 1 1
read_data {data} nocoeff
include {coeffs}
set group all density/disc {rho_t}
neighbor {skin} bin
neigh_modify every 1 delay 0 check yes
group mobile type 1
group bottom type 2
group top type 3
timestep {dt}
fix integrate mobile nve/bpm/sphere disc
fix damp mobile damping/cundall {alpha} {alpha}
fix drive top move linear 0.0 {vy} 0.0
fix plane all enforce2d
compute ftop top reduce sum fy
compute fbot bottom reduce sum fy
fix rec all ave/time {every} 1 {every} c_ftop c_fbot file {rec}
thermo 0
"""


# ================================================================================================ LAMMPS worker

def _lammps_run(spec: dict) -> dict:
    """The compression in LAMMPS: setup (``run 0``, timed apart), then the steps in timed segments."""
    t0 = time.perf_counter()
    rec = pathlib.Path(spec["tmp"]) / "rec.txt"
    lmp = V._new_lammps()
    lmp.commands_string(_SETUP_2D.format(data=spec["data"], coeffs=spec["coeffs"], rho_t=V._r(spec["rho_t"]),
                                         skin=V._r(spec["skin"]), dt=V._r(spec["dt"]), alpha=V._r(spec["alpha"]),
                                         vy=V._r(-spec["speed"]), every=spec["every"], rec=rec))
    lmp.command("run 0")
    setup = time.perf_counter() - t0
    loop, sps, best, sps_cpu = V._timed_segments(lmp, spec["steps"])
    mass = float(np.sum(lmp.numpy.extract_atom("rmass")[: int(lmp.extract_global("nlocal"))]))
    lmp.command("unfix rec")  # flushes and closes the file
    lmp.close()
    data = np.loadtxt(rec, comments="#", ndmin=2)
    data = data[data[:, 0] > 0]
    return {"steps": spec["steps"], "loop_time": loop, "setup_time": setup, "steps_per_second": sps,
            "steps_per_second_best": best, "steps_per_second_cpu": sps_cpu, "total_mass": mass,
            "step": data[:, 0].astype(int).tolist(), "f_top": data[:, 1].tolist(), "f_bottom": data[:, 2].tolist()}


def lammps_worker(spec_path: str) -> int:
    spec = json.loads(pathlib.Path(spec_path).read_text())
    V._pin_one_core(spec.get("cpu"))
    out = _lammps_run(spec)
    pathlib.Path(spec["out"]).write_text(json.dumps(out))
    return 0


def _call_worker(python: str, spec: dict, tmp: pathlib.Path) -> subprocess.CompletedProcess:
    path = tmp / "spec_2d.json"
    path.write_text(json.dumps(spec))
    return subprocess.run([python, str(pathlib.Path(__file__).resolve()), "--lammps-worker", str(path)],
                          env=V._lammps_env(python), capture_output=True, text=True)


# ================================================================================================ driver side

def _sample(n: int, shape: str, seed: int, mats: dict, path: str | None):
    """The disc packing (loaded from ``path`` if it exists, else generated and saved there) and its generation
    time."""
    import jaxbpm

    if path and pathlib.Path(path).exists():
        return jaxbpm.io.load_sample(path), 0.0
    t = time.perf_counter()
    aspect = (1, 2) if shape == "rectangle" else None
    s = jaxbpm.generate.disc_packing(n, shape, seed=seed, aspect=aspect, materials=mats,
                                     density=DENSITY).largest_cluster()
    t = time.perf_counter() - t
    if path:
        jaxbpm.io.save_sample(path, s)
    return s, t


def _jaxbpm_run(jaxbpm, sample, scene, args, pad: bool = True) -> tuple[dict, object]:
    """One DEM solve, timed once: the call's wall time beside the result's compile and run (steps) time. ``pad``: the
    DEM's option (a bonds-only run on the sample padded to its size class, the default)."""
    marks = []  # after each jitted chunk: steps done, wall and CPU time

    def progress(done, total, elapsed):
        marks.append((done, elapsed, time.process_time()))

    t0 = time.perf_counter()
    r = jaxbpm.solve(sample, scene, "dem", transits=args.transits, damping=args.damping, safety=args.safety,
                     progress=progress, throw=False, pad=pad)
    call = time.perf_counter() - t0
    st = r.stats
    chunk = [(d1 - d0) / (t1 - t0) for (d0, t0, _), (d1, t1, _) in zip(marks, marks[1:])]
    cpu = ((marks[-1][0] - marks[0][0]) / (marks[-1][2] - marks[0][2]) if len(marks) > 1 and
           marks[-1][2] > marks[0][2] else float("nan"))
    return {"steps": int(st["steps"]), "dt": st["dt"], "dt_crit": st["dt_crit"], "speed": st["speed"],
            "call_wall_time": call, "wall_time": r.wall_time, "compile_time": r.compile_time, "run_time": r.run_time,
            "setup_time": r.wall_time - r.compile_time - r.run_time, "steps_per_second": st["steps_per_second"],
            "steps_per_second_best": max(chunk) if chunk else st["steps_per_second"], "steps_per_second_cpu": cpu,
            "chunks": len(marks), "status": str(r.status), "stiffness": r.stiffness, "youngs_modulus": r.youngs_modulus,
            "total_mass": float(np.sum(sample.mass))}, r


def _rates(run: dict, nb: int, npart: int) -> dict:
    return {"bond_steps_per_second": run["steps_per_second"] * nb,
            "bond_steps_per_second_best": run["steps_per_second_best"] * nb,
            "bond_steps_per_second_cpu": run["steps_per_second_cpu"] * nb,
            "particle_steps_per_second": run["steps_per_second"] * npart}


def _bonds_scene(args) -> int:
    t_start = time.perf_counter()
    cpu = V._pin_one_core(args.cpu)
    V._xla_one_thread()
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxbpm
    from jaxbpm.interop.formats import write_lammps_coeffs, write_lammps_data
    from jaxbpm.scenes import UniaxialCompression

    n = args.n or (2000 if args.quick else 10000)
    out = pathlib.Path(args.out or f"results/vs_lammps_2d{'_quick' if args.quick else ''}.json")
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="jaxbpm_vs_lammps_2d_"))
    lmp_py, lmp_info = (None, "disabled (--no-lammps)") if args.no_lammps else V.find_lammps(args.lammps_python, tmp)
    if lmp_py is None:
        print(f"LAMMPS: not available -- {lmp_info}; reporting jaxbpm only", file=sys.stderr)
    sample, t_gen = _sample(n, "rectangle", args.seed, BOND_MATS, args.sample_file)
    nb, npart = sample.n_bonds, sample.n_particles
    scene = UniaxialCompression(axis=1, strain=args.strain, boundary="layers")
    fixed, driven = scene.layers(sample)
    length, area = scene.geometry(sample)
    target = scene.strain * length
    print(f"sample: {npart} discs, {nb} bonds (generated in {t_gen:.1f} s); l = {length:.5g} m, A = {area:.5g} m^2; "
          f"layers {int(fixed.sum())} / {int(driven.sum())}; core {cpu}", file=sys.stderr, flush=True)

    runs = {}
    for pad in (True, False):  # the default (padded to the size class), then the sample's own size
        jr, r = _jaxbpm_run(jaxbpm, sample, scene, args, pad)
        jr["stress_final"] = float(np.interp(target, np.asarray(r.displacement), np.asarray(r.force)) / area)
        jr.update(_rates(jr, nb, npart), padded_to=r.stats.get("padded_to"))
        runs[pad] = jr
        print(f"  jaxbpm (pad={pad}): {jr['steps']} steps, call {jr['call_wall_time']:.2f} s (compile "
              f"{jr['compile_time']:.2f} s, run {jr['run_time']:.2f} s)", file=sys.stderr, flush=True)
    jx, jx_np = runs[True], runs[False]

    lm = None
    if lmp_py is not None:
        data, coeffs = tmp / "discs.data", tmp / "coeffs.lmp"
        btype, table = V.ucs_bond_table(sample)
        atype = np.where(fixed, 2, np.where(driven, 3, 1))  # 1 mobile, 2 bottom (clamped), 3 top (driven)
        write_lammps_data(data, sample, atom_types=atype, bond_types=btype, coefficients=False)
        write_lammps_coeffs(coeffs, table, bond_style="bpm/rotational break no smooth no")
        spec = {"cpu": cpu, "tmp": str(tmp), "out": str(tmp / "lammps_out.json"), "data": str(data),
                "coeffs": str(coeffs), "rho_t": DENSITY * sample.thickness, "skin": float(np.mean(sample.radii)),
                "dt": jx["dt"], "speed": jx["speed"], "steps": jx["steps"], "alpha": args.damping,
                "every": max(1, jx["steps"] // 2000)}
        p = _call_worker(lmp_py, spec, tmp)
        if p.returncode != 0:
            sys.stderr.write(p.stderr[-4000:])
            raise RuntimeError(f"LAMMPS worker failed (exit {p.returncode}); its stderr is above")
        lm = json.loads((tmp / "lammps_out.json").read_text())
        step = np.asarray(lm.pop("step"))
        disp = jx["speed"] * step * jx["dt"]
        react = np.zeros((len(step), 2, 2))
        react[:, 0, 1], react[:, 1, 1] = lm.pop("f_top"), lm.pop("f_bottom")
        force = scene.compressive_force(react)
        lm["stiffness"] = scene.fit_stiffness(disp, force, target)
        lm["youngs_modulus"] = lm["stiffness"] * length / area
        lm["stress_final"] = float(np.interp(target, disp, force) / area)
        lm["wall_time"] = lm["setup_time"] + lm["loop_time"]
        lm["run_time"] = lm["loop_time"]
        lm.update(_rates(lm, nb, npart))
        lm["info"] = lmp_info
    res = {"benchmark": "vs_lammps_2d", "scene": "bonds",
           "machine": "shared (2 cores, other jobs running): rates are noisy; CPU-time rates the least",
           "sample": {"n_discs": npart, "n_bonds": nb, "seed": args.seed, "shape": "rectangle 1:2",
                      "thickness": sample.thickness, "generation_time": t_gen,
                      "lammps_bond_types": None if lm is None else int(len(table))},
           "loading": {"axis": 1, "strain": scene.strain, "transits": args.transits, "dt": jx["dt"],
                       "speed": jx["speed"], "steps": jx["steps"], "damping": args.damping, "safety": args.safety,
                       "gauge_length": length, "area": area, "cpu": cpu, "xla_flags": os.environ.get("XLA_FLAGS")},
           "jaxbpm": {"version": getattr(jaxbpm, "__version__", "?"), "git": V._git_state(), **jx},
           "jaxbpm_unpadded": jx_np, "lammps": lm}
    if lm is not None:
        res["comparison"] = {
            "bond_steps_ratio_jaxbpm_over_lammps": jx["steps_per_second"] / lm["steps_per_second"],
            "bond_steps_ratio_cpu_time": jx["steps_per_second_cpu"] / lm["steps_per_second_cpu"],
            "bond_steps_ratio_best": jx["steps_per_second_best"] / lm["steps_per_second_best"],
            "bond_steps_ratio_unpadded": jx_np["steps_per_second"] / lm["steps_per_second"],
            "bond_steps_ratio_unpadded_cpu_time": jx_np["steps_per_second_cpu"] / lm["steps_per_second_cpu"],
            "youngs_modulus_ratio": jx["youngs_modulus"] / lm["youngs_modulus"],
            "stress_final_ratio": jx["stress_final"] / lm["stress_final"],
            "mass_ratio": jx["total_mass"] / lm["total_mass"]}
    res["total_time"] = time.perf_counter() - t_start
    _print_bonds(res, jx, jx_np, lm)
    _write(out, res)
    print(f"\nwrote {out}  (total {res['total_time']:.1f} s)", file=sys.stderr)
    shutil.rmtree(tmp, ignore_errors=True)
    return 0


def _write(out: pathlib.Path, res: dict) -> None:
    from _common import write_json  # atomic, with the peak resident set

    write_json(out, res)


def _print_bonds(res: dict, jx: dict, jx_np: dict, lm: dict | None) -> None:
    ld = res["loading"]
    print(f"\njaxbpm vs LAMMPS, 2D (dimension 2, discs) -- uniaxial compression to {ld['strain']:g}, "
          f"{res['sample']['n_discs']} discs, {res['sample']['n_bonds']} bonds, bonds only, one thread each "
          f"(core {ld['cpu']}; {res['machine']})")
    print(f"dt = {ld['dt']:.4g} s (0.5 x jaxbpm's critical step), {ld['steps']} steps ({ld['transits']:g} transits), "
          f"Cundall damping {ld['damping']}")
    rows = [("steps", "steps", "d"), ("wall time of the call [s]", "call_wall_time", ".2f"),
            ("  setup [s]", "setup_time", ".2f"), ("  compile [s]", "compile_time", ".2f"),
            ("  run (steps) [s]", "run_time", ".2f"), ("bond-steps/s (median)", "bond_steps_per_second", ".4g"),
            ("bond-steps/s (best)", "bond_steps_per_second_best", ".4g"),
            ("bond-steps/s (CPU time)", "bond_steps_per_second_cpu", ".4g"),
            ("particle-steps/s", "particle_steps_per_second", ".4g"), ("E [Pa]", "youngs_modulus", ".6g"),
            (f"stress at strain {ld['strain']:g} [Pa]", "stress_final", ".6g"),
            ("total mass [kg]", "total_mass", ".6g")]
    if lm is not None:
        lm.setdefault("call_wall_time", lm["wall_time"])
        lm.setdefault("compile_time", None)
    print(f"{'':<28} {'jaxbpm':>14} {'pad=False':>14} {'LAMMPS':>14} {'jaxbpm/LAMMPS':>14} {'pad=False/LAMMPS':>17}")
    for label, key, spec in rows:
        a, a2, b = jx.get(key), jx_np.get(key), (lm or {}).get(key)
        ratio = f"{a / b:>14.4f}" if isinstance(a, float) and isinstance(b, float) and b else f"{'':>14}"
        ratio2 = f"{a2 / b:>17.4f}" if isinstance(a2, float) and isinstance(b, float) and b else f"{'':>17}"
        print(f"{label:<28} {V._fmt(a, spec):>14} {V._fmt(a2, spec):>14} {V._fmt(b, spec):>14} {ratio} {ratio2}")
    print(f"(jaxbpm: setup = wall - compile - run of solve; padded to {jx.get('padded_to')} (particles, bonds) by "
          "default, pad=False: the sample's own size; LAMMPS: setup = read_data ... run 0, no compile)")


def _beam_scene(args) -> int:
    t_start = time.perf_counter()
    cpu = V._pin_one_core(args.cpu)
    V._xla_one_thread()
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxbpm
    from jaxbpm.scenes import ThreePointBending

    out = pathlib.Path(args.out or "results/beam_2d.json")
    sample, t_gen = _sample(args.beam_n, "beam", args.seed, BEAM_MATS, args.sample_file)
    r_mean = float(np.mean(sample.radii))  # wider than the defaults: a random packing leaves gaps
    scene = ThreePointBending(axis=1, span_axis=0, contact_law="linear", support_width=4 * r_mean,
                              punch_width=4 * r_mean, layer_thickness=2 * r_mean)
    print(f"beam: {sample.n_particles} discs, {sample.n_bonds} bonds (generated in {t_gen:.1f} s); core {cpu}",
          file=sys.stderr, flush=True)
    t0, c0 = time.perf_counter(), time.process_time()
    marks = []
    r = jaxbpm.solve(sample, scene, "dem",
                     progress=lambda done, total, el: marks.append((done, el, time.process_time())))
    call, call_cpu = time.perf_counter() - t0, time.process_time() - c0
    cpu_rate = ((marks[-1][0] - marks[0][0]) / (marks[-1][2] - marks[0][2]) if len(marks) > 1 and
                marks[-1][2] > marks[0][2] else float("nan"))
    st = r.stats
    row = {"n_discs": sample.n_particles, "n_bonds": sample.n_bonds, "steps": int(st["steps"]),
           "call_wall_time": call, "call_cpu_time": call_cpu, "wall_time": r.wall_time,
           "compile_time": r.compile_time, "run_time": r.run_time,
           "setup_time": r.wall_time - r.compile_time - r.run_time, "stop_reason": st.get("stop_reason"),
           "steps_per_second": st["steps_per_second"], "bond_steps_per_second": st["steps_per_second"] * sample.n_bonds,
           "steps_per_second_cpu": cpu_rate, "steps_planned": st.get("steps_planned"), "dt": st["dt"],
           "flexural_strength": st.get("strength"), "peak_force": float(np.max(r.force)),
           "broken_bonds": int(st.get("broken_tensile", 0) + st.get("broken_shear", 0)), "generation_time": t_gen}
    res = {"benchmark": "vs_lammps_2d", "scene": "beam", "cpu": cpu, "xla_flags": os.environ.get("XLA_FLAGS"),
           "machine": "shared (2 cores, other jobs running)", "scene_args": "ThreePointBending(axis=1, span_axis=0, "
           "contact_law='linear', support_width=punch_width=4 r, layer_thickness=2 r), DEM defaults",
           "materials": BEAM_MATS, "jaxbpm": row}
    print(f"\n2D three-point bending to failure, {row['n_discs']} discs, {row['n_bonds']} bonds, linear contacts, "
          f"one thread (core {cpu}; machine shared)")
    for k in ("steps", "steps_planned", "dt", "steps_per_second_cpu", "call_wall_time", "call_cpu_time", "setup_time",
              "compile_time", "run_time", "stop_reason", "bond_steps_per_second", "peak_force", "flexural_strength",
              "broken_bonds"):
        print(f"  {k:<24} {row[k]}")
    res["total_time"] = time.perf_counter() - t_start
    _write(out, res)
    print(f"\nwrote {out}  (total {res['total_time']:.1f} s)", file=sys.stderr)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", choices=("bonds", "beam"), default="bonds")
    ap.add_argument("--n", type=int, default=None, help="discs of the bonds scene (default 10 000; --quick 2000)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--strain", type=float, default=2e-3)
    ap.add_argument("--transits", type=float, default=20.0, help="loading duration in elastic-wave transit times")
    ap.add_argument("--damping", type=float, default=0.7, help="local (Cundall) damping alpha, both codes")
    ap.add_argument("--safety", type=float, default=0.5, help="dt = safety x jaxbpm's critical time step")
    ap.add_argument("--sample-file", default=None, help="HDF5 sample: loaded if it exists, else generated and saved")
    ap.add_argument("--lammps-python", default=None, help="Python with the lammps module")
    ap.add_argument("--no-lammps", action="store_true")
    ap.add_argument("--beam-n", type=int, default=20000, help="discs of the beam")
    ap.add_argument("--out", default=None)
    ap.add_argument("--cpu", type=int, default=None, help="the core to pin both codes to (default: the lowest)")
    ap.add_argument("--lammps-worker", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.lammps_worker:
        return lammps_worker(args.lammps_worker)
    return _bonds_scene(args) if args.scene == "bonds" else _beam_scene(args)


if __name__ == "__main__":
    sys.exit(main())
