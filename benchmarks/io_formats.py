"""File I/O speed and size: write + read of a 100k-particle bonded sample as LAMMPS data, CSV and HDF5, and a time
series as VTKHDF (topology once) against VTU (one file per step).

The sample is a simple-cubic lattice with jittered centres and radii (built directly: packing 100k random spheres
takes about a minute and does not change what is timed). Each case runs ``--repeat`` times; the best time counts.
The series cases write ``--steps`` steps of moving points with point and bond data, for the large sample and for a
small one (``--series-n``), and report file sizes.

    python benchmarks/io_formats.py [--n 100000] [--steps 10] [--series-n 2000] [--repeat 3] [--out ...]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import tempfile
import time

import numpy as np

from _common import enable_x64, machine_info, table, write_json

# the per-line LAMMPS data reader and writer that the section-at-a-time ones replaced, at 100k particles [s]
OLD_LAMMPS_100K = {"read_s": 12.6, "write_s": 4.5}


def lattice_sample(n: int, seed: int = 0):
    """About ``n`` particles on a simple-cubic lattice (spacing 2 mm), centres and radii jittered, bonded to their
    six neighbours."""
    from jaxbpm import generate
    from jaxbpm.sample import Sample

    side = max(2, round(n ** (1 / 3)))
    base = generate.lattice("sc", (side, side, max(2, round(n / side**2))), 1e-3)
    rng = np.random.default_rng(seed)
    m = base.n_particles
    pos = np.asarray(base.positions) + 2e-5 * rng.standard_normal((m, 3))
    rad = np.asarray(base.radii) * (1 + 0.01 * rng.random(m))
    return Sample.from_arrays(pos, rad, base.bonds, bond_radius_ratio=0.5,
                              materials={"E": [1e9], "nu": [0.25], "tensile_strength": [5e6],
                                         "shear_strength": [8e6]})


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def file_cases(sample, tmp: pathlib.Path, repeat: int) -> list[dict]:
    from jaxbpm import io
    from jaxbpm.interop import formats

    cases = {"LAMMPS data": (tmp / "s.data", formats.write_lammps_data, formats.read_lammps_data),
             "CSV": (tmp / "s.csv", formats.write_csv, formats.read_csv),
             "HDF5": (tmp / "s.h5", io.save_sample, io.load_sample)}
    rows = []
    for name, (path, write, read) in cases.items():
        w = best(lambda: write(path, sample), repeat)
        r = best(lambda: read(path), repeat)
        size = sum(p.stat().st_size for p in tmp.glob(path.stem + "*"))
        rows.append({"format": name, "particles": sample.n_particles, "bonds": sample.n_bonds, "write_s": w,
                     "read_s": r, "size_mib": size / 2**20})
        print(f"{name}: write {w:.3g} s, read {r:.3g} s", file=sys.stderr, flush=True)
    return rows


def series_cases(sample, tmp: pathlib.Path, steps: int) -> list[dict]:
    from jaxbpm.interop import formats

    n, nb = sample.n_particles, sample.n_bonds
    rng = np.random.default_rng(1)
    frames = [{"displacement": 1e-5 * k * rng.standard_normal((n, 3)), "intact": rng.random(nb) > 0.01 * k,
               "point_data": {"velocity": rng.standard_normal((n, 3))}, "bond_data": {"force": rng.random(nb)}}
              for k in range(steps)]
    rows = []
    for name in ("VTU (.pvd + one .vtu a step)", "VTKHDF (one file)"):
        out = tmp / f"series_{n}"
        out.mkdir()
        t0 = time.perf_counter()
        if name.startswith("VTU"):
            series = formats.VTUSeries(out / "run.pvd", sample)
            for k, f in enumerate(frames):
                series.write(0.1 * k, **f)
        else:
            with formats.VTKHDFSeries(out / "run.vtkhdf", sample) as series:
                for k, f in enumerate(frames):
                    series.write(0.1 * k, **f)
        elapsed = time.perf_counter() - t0
        size = sum(p.stat().st_size for p in out.iterdir())
        rows.append({"format": name, "particles": n, "bonds": nb, "steps": steps, "write_s": elapsed,
                     "size_mib": size / 2**20})
        print(f"{name}, n={n}: {elapsed:.3g} s, {size / 2**20:.3g} MiB", file=sys.stderr, flush=True)
        for p in out.iterdir():
            p.unlink()
        out.rmdir()
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=100_000, help="particles of the large sample")
    ap.add_argument("--steps", type=int, default=10, help="steps of the series cases")
    ap.add_argument("--series-n", type=int, default=2000, help="particles of the small series case")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default="results/io_formats.json")
    args = ap.parse_args(argv)
    enable_x64()

    big = lattice_sample(args.n)
    with tempfile.TemporaryDirectory() as tmp:
        files = file_cases(big, pathlib.Path(tmp), args.repeat)
        series = series_cases(lattice_sample(args.series_n), pathlib.Path(tmp), args.steps)
        series += series_cases(big, pathlib.Path(tmp), args.steps)
    table(files, ["format", "particles", "bonds", "write_s", "read_s", "size_mib"])
    table(series, ["format", "particles", "bonds", "steps", "write_s", "size_mib"])
    lammps = next(r for r in files if r["format"] == "LAMMPS data")
    scale = big.n_particles / 100_000
    speedup = {k: OLD_LAMMPS_100K[k] * scale / lammps[k] for k in ("read_s", "write_s")}
    print(f"LAMMPS data against the per-line code (scaled to {big.n_particles} particles): read "
          f"{speedup['read_s']:.1f}x, write {speedup['write_s']:.1f}x faster")
    out = {"benchmark": "io_formats", "machine": machine_info(), "files": files, "series": series,
           "lammps_old_100k": OLD_LAMMPS_100K, "lammps_speedup": speedup}
    print(json.dumps(out, indent=2, default=float))
    path = write_json(args.out, out)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
