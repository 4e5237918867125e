"""DEM throughput: bond-steps and particle-steps per second for bonded random samples.

For each size (default 1k, 10k, 100k particles) and each physics set (bonds only; bonds + Hertz-Mindlin contacts
with a neighbour list), the script runs the jitted DEM chunk of a uniaxial compression and reports compile time and
steady-state throughput separately (timed with block_until_ready, median over chunks). The compression advances
``--strain-per-step`` (2e-6) every step at every size: with contacts the platen's motion per step sets how often the
candidate lists are found again, so a rate tied to the run's length (as before: 0.2 % over ``--steps``) made short
runs on large samples look slower than they are.

    python benchmarks/dem_throughput.py [--sizes 1000 10000 100000] [--steps 2000] [--threads 1] [--out ...]
    python benchmarks/dem_throughput.py --samples results/samples/box_1000000_phi0.55_seed0.h5 --steps 200 \
        --physics bonds                      # samples from files (e.g. the ones scaling.py stored) instead
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

from _common import enable_x64, machine_info, peak_rss_gib, pin_threads, profile_top, table, write_json


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000])
    ap.add_argument("--steps", type=int, default=2000, help="timed steps per case (after compilation)")
    ap.add_argument("--chunk", type=int, default=250)
    ap.add_argument("--threads", type=int, default=None, help="pin to this many cores (default: all)")
    ap.add_argument("--physics", nargs="+", default=["bonds", "bonds+contacts"],
                    choices=["bonds", "bonds+contacts"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--samples", nargs="+", default=None, metavar="H5",
                    help="sample files (jaxbpm.io.save_sample) to run instead of generating --sizes")
    ap.add_argument("--strain-per-step", type=float, default=2e-6,
                    help="compression per step (default 2e-6: 0.2 %% over 1000 steps; before, 0.2 %% over --steps)")
    ap.add_argument("--contact-list", choices=["auto", "host", "jax-md"], default="auto",
                    help="the candidate list of contacts: built on the host (a k-d tree, between steps; the CPU's "
                         "default) or by jax-md's cell list inside the step (the accelerators')")
    ap.add_argument("--profile", default=None, metavar="DIR",
                    help="after each timed run, trace one more chunk with JAX's profiler into DIR/<case> and record "
                         "the operations (XLA fusions, GPU kernels) that took longest, per step")
    ap.add_argument("--quick", action="store_true", help="1k and 10k particles, 500 timed steps")
    ap.add_argument("--out", default="results/dem_throughput.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.sizes, args.steps = [1000, 10000], 500
        if args.out == "results/dem_throughput.json":
            args.out = "results/dem_throughput_quick.json"
    pin_threads(args.threads)
    enable_x64()

    import jaxbpm
    from jaxbpm import dem
    from jaxbpm.physics.model import default_params

    from jaxbpm.io import load_sample

    if args.contact_list != "auto":
        from jaxbpm.dem import neighbors

        neighbors.HOST_LIST_MIN = 0 if args.contact_list == "host" else 1 << 62

    rows = []
    for n in (args.samples or args.sizes):
        t0 = time.perf_counter()
        if args.samples:
            sample = load_sample(n)
        else:
            sample = jaxbpm.generate.box(n, seed=args.seed, mean_radius=1e-3, radius_spread=0.05)
        gen_time = time.perf_counter() - t0
        params = default_params(sample)
        for physics in args.physics:
            scene = jaxbpm.scenes.UniaxialCompression(strain=0.002, contacts=physics != "bonds")
            model = scene.model(sample)
            dt = 0.5 * dem.critical_time_step(model, params)
            length, _ = scene.geometry(sample)
            # a slow compression, so the sample deforms while we time it: the same strain per step at every size and
            # step count (with contacts, the platen's motion per step sets how often the lists are found again)
            load = scene.loading(sample, speed=args.strain_per_step * length / dt)
            steps = max(args.steps, 2 * args.chunk)
            _, _, stats = dem.simulate(model, params, load, dt=dt, n_steps=steps + args.chunk, chunk=args.chunk,
                                       damping=0.7)
            sps = stats["steps_per_second"]
            row = {"particles": sample.n_particles, "bonds": sample.n_bonds, "physics": physics,
                   "rotations": model.rotations, "compile_s": stats["compile_time"], "steps": stats["steps"],
                   "strain_per_step": args.strain_per_step,
                   "steps_per_s": sps, "bond_steps_per_s": sps * sample.n_bonds,
                   "particle_steps_per_s": sps * sample.n_particles,
                   # the whole loop (list rebuilds between chunks included) against the median chunk above
                   "run_steps_per_s": stats["steps"] / stats["run_time"],
                   "contact_capacity": stats["contact_capacity"], "contact_list": stats["contact_list"],
                   "contact_rebuilds": stats["contact_rebuilds"], "contact_slots": stats["contact_slots"],
                   "contacts_within_reach": stats["contacts_within_reach"],
                   "contacts_refound": stats["contacts_refound"], "reallocations": stats["reallocations"],
                   ("load_s" if args.samples else "generate_s"): gen_time,
                   "peak_rss_gib": peak_rss_gib()}
            if args.profile:
                import jax

                trace = os.path.join(args.profile, f"{sample.n_particles}_{physics.replace('+', '_')}")
                try:  # (a profiler that cannot start, e.g. without CUPTI on a GPU, costs the profile, not the row)
                    with jax.profiler.trace(trace, create_perfetto_trace=True):
                        dem.simulate(model, params, load, dt=dt, n_steps=args.chunk, chunk=args.chunk, damping=0.7)
                    row["profile_top"] = profile_top(trace, steps=args.chunk)
                except Exception as exc:  # noqa: BLE001
                    row["profile_top"], row["profile_error"] = [], f"{type(exc).__name__}: {exc}"[:500]
                    print(f"  profile failed: {row['profile_error']}", file=sys.stderr)
                for op in row["profile_top"][:12]:
                    print(f"  {op['ms_per_step']:9.3f} ms/step  {op['calls_per_step']:6.2f}x  {op['name']}",
                          file=sys.stderr)
            rows.append(row)
            print(f"n={sample.n_particles} nb={sample.n_bonds} {physics}: {row['bond_steps_per_s']:.3g} bond-steps/s,"
                  f" compile {row['compile_s']:.2f} s", file=sys.stderr, flush=True)
    table(rows, ["particles", "bonds", "physics", "compile_s", "steps_per_s", "bond_steps_per_s",
                 "particle_steps_per_s", "peak_rss_gib"])
    out = {"benchmark": "dem_throughput", "machine": machine_info(), "threads": args.threads, "results": rows}
    print(json.dumps(out, indent=2, default=float))
    path = write_json(args.out, out)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
