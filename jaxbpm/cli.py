"""The ``jaxbpm`` command: generate, inspect and export bonded samples, and run the demo.

Run ``jaxbpm --help`` (or ``python -m jaxbpm --help``) for the sub-commands. The command turns on JAX float64
when it starts, and JAX's persistent compilation cache (:func:`jaxbpm.enable_compilation_cache`; ``--no-cache``
to leave it off, ``--cache-dir DIR`` for another directory); library code never changes JAX settings. Errors about
samples and files are printed as one ``error: ...`` line on stderr with exit code 2; argparse usage errors also
exit with 2. JAX is imported only when a command runs: ``--help`` and ``--version`` answer at once. Options given on
the command line override a ``--config`` file, which overrides the defaults.
"""

from __future__ import annotations

import argparse
import functools
import pathlib
import sys
import time
from typing import Any, Sequence

from jaxbpm.errors import JaxbpmError

__all__ = ["main", "build_parser", "run_demo"]

_RANDOM_SHAPES = ("box", "cylinder", "beam")
_LATTICE_SHAPES = ("sc", "fcc")
# Defaults of the `generate` options (kept here so `--help` shows them and the command behaves the same whatever
# the library defaults are); None = not passed, the generator decides.
_GENERATE_DEFAULTS = {"mean_radius": None, "spread": 0.05, "packing_fraction": None, "bond_radius_ratio": 0.5,
                      "E": 1.0e9, "nu": 0.25}
_DEMO_DIR = "jaxbpm-demo"
_DEMO_FILES = ("demo_sample.h5", "demo_results.json", "demo_speed_accuracy.png")  # what the demo writes there
# the demo's methods: label (in demo_results.json) -> what it is
_DEMO_NAMES = {"dem": "DEM, explicit discrete element method (time integration; the reference)",
               "dsm": "DSM, direct stiffness method (static equilibrium, default tolerance)",
               "dsm stol 1e-3": "DSM with stiffness_tol=1e-3 (stops once the stiffness settles to 0.1 %)",
               "ste": "STE, stiffness tensor estimate (local tensors, no global solve)"}
_FORCE_HELP = "replace an existing sample or record at the output path (never an input of the command)"


# ---------------------------------------------------------------------------------------------- commands
def _generate_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword arguments of ``jaxbpm.generate.from_shape`` that apply to ``args.shape``."""
    opts = {k: (v if (v := getattr(args, k)) is not None else d) for k, d in _GENERATE_DEFAULTS.items()}
    kw: dict[str, Any] = {"bond_radius_ratio": opts["bond_radius_ratio"],
                          "materials": {"E": opts["E"], "nu": opts["nu"]}}
    if args.shape in _LATTICE_SHAPES:
        ignored = [f"--{k.replace('_', '-')}" for k in ("spread", "packing_fraction") if getattr(args, k) is not None]
        if ignored:
            print(f"note: {', '.join(ignored)} ignored for the {args.shape} lattice", file=sys.stderr)
        if opts["mean_radius"] is not None:
            kw["radius"] = opts["mean_radius"]
    else:
        kw.update(radius_spread=opts["spread"], packing_fraction=opts["packing_fraction"])
        if opts["mean_radius"] is not None:
            kw["mean_radius"] = opts["mean_radius"]
    return kw


def _cmd_generate(args: argparse.Namespace) -> int:
    from jaxbpm import generate
    from jaxbpm._outputs import check_outputs
    from jaxbpm.io import save_sample

    check_outputs({"--out": args.out}, {}, force=args.force)  # before the packing, which can take minutes
    if args.bond_radius_ratio is not None and args.bond_radius_ratio > 1:
        from jaxbpm.errors import SampleError

        raise SampleError(f"--bond-radius-ratio {args.bond_radius_ratio:g} > 1: bonds wider than the smaller of their "
                          "particles (Sample.from_arrays(..., wide_bonds=True) builds such a sample)")
    start = time.perf_counter()
    sample = generate.from_shape(args.shape, args.n, seed=args.seed, progress=not args.quiet,
                                 **_generate_kwargs(args))
    out = save_sample(args.out, sample)
    print(sample.summary())
    print(f"wrote {out}  ({time.perf_counter() - start:.2f} s)")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from jaxbpm.io import load_sample

    if args.sample is None and not args.cache:
        args.usage_error("give a sample file, or --cache")
    if args.sample is not None:
        sample = load_sample(args.sample)
        print(f"sample file          {args.sample}")
        print(sample.summary())
    if args.cache:
        _print_cache_info(args)
    return 0


def _print_cache_info(args: argparse.Namespace) -> None:
    """The compilation cache in effect (or, when off, the default one): directory, entries, size."""
    from jaxbpm._cache import compilation_cache_dir, default_cache_dir, usage

    directory = compilation_cache_dir()
    if directory is not None:
        state = "on" if not args.no_cache else "on (set through JAX's own settings)"
    else:
        directory = args.cache_dir if args.cache_dir is not None else default_cache_dir()
        state = "off (--no-cache)" if args.no_cache else "off (the directory cannot be used)"
    entries, size = usage(directory)
    print(f"compilation cache    {state}")
    print(f"cache directory      {directory}")
    print(f"cached programs      {entries}")
    print(f"cache size           {_human_bytes(size)}")


def _human_bytes(n: int) -> str:
    if n < 1000:
        return f"{n} bytes"
    for unit in ("kB", "MB", "GB"):
        n /= 1000
        if n < 1000:
            break
    return f"{n:.1f} {unit}"


def _cmd_export_vtk(args: argparse.Namespace) -> int:
    from jaxbpm._outputs import check_outputs
    from jaxbpm.io import export_vtk, load_sample

    check_outputs({"OUT": args.out}, {"SAMPLE": args.sample}, force=args.force)
    sample = load_sample(args.sample)
    out = export_vtk(args.out, sample)
    print(f"wrote {out}  ({sample.n_particles} particles as vertices, {sample.n_bonds} bonds as lines)")
    return 0


def run_demo(out_dir, n: int = 2000, seed: int = 0, quiet: bool = False, solve: bool = True,
             calibrate: bool = True, target_factor: float = 1.25) -> dict[str, Any]:
    """The demo: generate a random box sample, solve it three ways, calibrate its bond modulus.

    Generates a random box sample of ``n`` particles (at the generator's automatic packing fraction; the time the
    generation took is printed), saves it to ``out_dir/demo_sample.h5``, then compresses it uniaxially (0.2 % strain,
    clamped layers) with the three methods -- the explicit DEM (the reference), the direct stiffness method (at its
    default tolerance and with ``stiffness_tol=1e-3``) and the stiffness tensor estimate -- and reports each one's
    stiffness, difference to the DEM and cost; then calibrates the bond modulus to a target Young's modulus
    (``target_factor`` x the DEM's) with the multi-fidelity path, checked by one DEM run. Writes
    ``demo_results.json`` and the speed-against-accuracy chart ``demo_speed_accuracy.png``.

    Args:
      out_dir: the folder the files go to (made if missing).
      n: particles of the sample.
      seed: the generator's seed.
      quiet: no progress bars.
      solve: solve the sample (else only generate and save it).
      calibrate: calibrate the bond modulus after the solves.
      target_factor: the target Young's modulus over the DEM's.

    Returns:
      ``{"out_dir": Path, "sample_path": Path, "sample": Sample, "results": {label: Result},
      "calibration": CalibrationResult or None}``.
    """
    import numpy as np

    import jaxbpm
    from jaxbpm import generate
    from jaxbpm.io import save_sample, write_json

    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    sample = generate.from_shape("box", n, seed=seed, progress=not quiet)
    generated = time.perf_counter() - start
    path = save_sample(out_dir / "demo_sample.h5", sample)
    summary = sample.summary()
    print(summary)
    print(f"generated the sample in {generated:.2f} s; wrote {path}")
    out: dict[str, Any] = {"out_dir": out_dir, "sample_path": path, "sample": sample, "results": {},
                           "calibration": None}
    if not solve:
        return out
    body = sample.largest_cluster() if summary.n_clusters > 1 else sample
    if body.n_particles < sample.n_particles:
        print(f"solving on the largest bonded cluster ({body.n_particles} of {sample.n_particles} particles)")
    scene = jaxbpm.scenes.UniaxialCompression(strain=0.002)
    runs = (("dem", "dem", {"progress": not quiet}), ("dsm", "dsm", {}),
            ("dsm stol 1e-3", "dsm", {"stiffness_tol": 1e-3}), ("ste", "ste", {}))
    for label, method, options in runs:
        print(f"\nuniaxial compression, {_DEMO_NAMES[label]} ...", flush=True)
        out["results"][label] = jaxbpm.solve(body, scene, method=method, **options)
    table = _demo_table(out["results"])
    dem = out["results"]["dem"]
    report: dict[str, Any] = {"particles": body.n_particles, "bonds": body.n_bonds, "strain": scene.strain,
                              "results": table}
    if calibrate:
        from jaxbpm.calibrate import calibrate as run_calibration

        target = target_factor * dem.youngs_modulus
        print(f"\ncalibrating the bond modulus to E = {target:.4g} Pa (multi-fidelity, checked by the DEM) ...",
              flush=True)
        cal = run_calibration(body, scene, {"youngs_modulus": target}, method="auto", tol=0.01, check="dem")
        out["calibration"] = cal
        print(cal.table())
        check = cal.info.get("check", {})
        for name, err in check.get("errors", {}).items():
            print(f"DEM check at the answer: {name} {100 * float(np.max(np.abs(err))) * np.sign(np.sum(err)):+.3f} % "
                  f"({check.get('wall_time', float('nan')):.2f} s)", flush=True)
        report["calibration"] = {"target_youngs_modulus": target, "values": cal.values, "method": cal.method,
                                 "evaluations": cal.evaluations, "levels": cal.levels, "wall_time": cal.wall_time,
                                 "errors": {k: float(np.max(np.abs(v))) for k, v in cal.errors.items()},
                                 "check": check, "notes": cal.notes}
    path_json = write_json(out_dir / "demo_results.json", report)
    print(f"wrote {path_json}")
    png = _demo_chart(out_dir / "demo_speed_accuracy.png", out["results"], body)
    print(f"wrote {png}")
    return out


def _demo_table(results: dict) -> list[dict]:
    """Print the demo's comparison (each method against the DEM, with run- and wall-time speed-ups) and its key;
    returns its rows."""
    dem = results["dem"]
    print(f"\n{'method':<15}{'K [N/m]':>13}{'E [Pa]':>13}{'vs DEM':>10}{'compile [s]':>13}{'run [s]':>10}"
          f"{'wall [s]':>10}{'run ratio':>11}{'wall ratio':>12}")
    table = []
    for label, res in results.items():
        diff = res.stiffness / dem.stiffness - 1.0
        run_ratio = dem.run_time / res.run_time if res.run_time > 0 else float("nan")
        wall_ratio = dem.wall_time / res.wall_time if res.wall_time > 0 else float("nan")
        print(f"{label:<15}{res.stiffness:>13.6g}{res.youngs_modulus:>13.6g}{100 * diff:>9.3f}%"
              f"{res.compile_time:>13.3f}{res.run_time:>10.4f}{res.wall_time:>10.3f}{run_ratio:>10.1f}x"
              f"{wall_ratio:>11.1f}x")
        table.append({"method": label, "description": _DEMO_NAMES[label], "stiffness": res.stiffness,
                      "youngs_modulus": res.youngs_modulus, "difference_to_dem": diff,
                      "compile_time": res.compile_time, "run_time": res.run_time, "wall_time": res.wall_time,
                      "speedup_run": run_ratio, "speedup_wall": wall_ratio})
    print("\n".join(f"  {label}: {name}" for label, name in _DEMO_NAMES.items()))
    print("  vs DEM: the stiffness's difference to the DEM's; run: the compiled program alone; wall: the whole call "
          "(setup + compile + run)\n  run ratio, wall ratio: the DEM's run or wall time over the method's (how many "
          "times faster)")
    return table


def _demo_chart(path, results: dict, sample):
    """Wall time against the error of E, one point per method, the DEM the reference (a dotted line: its own error
    is 0), run times hollow beside the wall times, the Pareto front marked (:func:`jaxbpm.plots.speed_accuracy`);
    saved atomically to ``path`` (the format from its suffix). Uses no global matplotlib state."""
    from jaxbpm.plots import save, speed_accuracy

    named = {f"{label}: {_DEMO_NAMES[label]}": res for label, res in results.items()}
    ax = speed_accuracy(named, reference=results["dem"], run_time=True)
    ax.set_title(f"speed against accuracy: {sample.n_particles} particles, {sample.n_bonds} bonds, uniaxial "
                 "compression\n(reference: the DEM; 'x faster': the DEM's time over the method's)", fontsize=9)
    return save(ax, path)


def _cmd_demo(args: argparse.Namespace) -> int:
    from jaxbpm._outputs import OutputPathError, check_outputs

    if args.out.exists() and not args.out.is_dir():
        raise OutputPathError(f"--out {args.out}: the file exists; the demo writes a folder, give a folder path")
    if args.out.is_dir():  # a demo folder is reused only with --force: its demo files replaced, nothing else
        earlier = [name for name in _DEMO_FILES if (args.out / name).exists()]
        if earlier and not args.force:
            raise OutputPathError(f"--out {args.out} holds an earlier demo's files ({', '.join(earlier)}): pass "
                                  "--force to replace them, or give another --out folder")
        check_outputs({f"--out ({name})": args.out / name for name in _DEMO_FILES}, {}, force=True)
        if earlier:
            print(f"replacing the earlier demo's files in {args.out} (--force): {', '.join(earlier)}")
    run_demo(args.out, n=args.n, seed=args.seed, quiet=args.quiet, solve=not args.no_solve,
             calibrate=not args.no_calibrate)
    return 0


# ---------------------------------------------------------------------------------------------- parser
def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {value}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The ``jaxbpm`` argument parser.

    Returns:
      An :class:`argparse.ArgumentParser` with one sub-parser per command (each command's options loaded on first
      use).
    """
    from jaxbpm._version import __version__

    parser = argparse.ArgumentParser(
        prog="jaxbpm",
        description="jaxbpm: bonded-particle models (bonded DEM) in JAX. Generate bonded samples, inspect them and "
                    "export them to ParaView.",
        epilog="Run 'jaxbpm COMMAND --help' for the options of a command. Units are SI (m, kg, Pa).")
    parser.add_argument("--version", action="version", version=f"jaxbpm {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=_CommandParser)

    _add_generate(sub)
    _add_info(sub)
    _add_export_vtk(sub)
    _add_demo(sub)

    # commands defined in packages that import JAX: their options are added when the command is used (or its
    # help shown), so that `jaxbpm --help` and the other commands' parsing stay free of JAX
    lazy = {name: sub.add_parser(name, help=text) for name, text in _LAZY_COMMANDS.items()}
    for name, parser_ in lazy.items():
        parser_.populate = functools.partial(_populate, lazy, _LAZY_LOADERS[name])
    # the cache options are global, accepted before the command and after it (SUPPRESS: an option absent after the
    # command does not overwrite the value given before it)
    _add_cache_options(parser, argparse.SUPPRESS)
    for name, command_parser in sub.choices.items():
        if name not in lazy:
            _add_cache_options(command_parser.add_argument_group("compilation cache"), argparse.SUPPRESS)
    parser.set_defaults(no_cache=False, cache_dir=None)
    return parser



def _add_generate(sub) -> None:
    """The ``generate`` command: a bonded sample saved to an HDF5 file."""
    d = _GENERATE_DEFAULTS
    p = sub.add_parser(
        "generate", help="generate a bonded sample and save it to an HDF5 file",
        description="Generate a bonded sample and save it to an HDF5 sample file. 'box', 'cylinder' and 'beam' are "
                    "random dense packings of polydisperse spheres; 'sc' and 'fcc' are regular lattices of equal "
                    "spheres (packing options are ignored for them). Neighbours in contact are bonded.")
    p.add_argument("--shape", required=True, choices=_RANDOM_SHAPES + _LATTICE_SHAPES,
                   help="shape of the sample: random packings box, cylinder, beam; lattices sc, fcc")
    p.add_argument("--n", required=True, type=_positive_int, help="number of particles (approximate for lattices)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="random seed (default: 0)")
    p.add_argument("--out", required=True, type=pathlib.Path, help="sample file to write, e.g. sample.h5")
    p.add_argument("--mean-radius", type=_positive_float, default=None, dest="mean_radius", metavar="R",
                   help="mean particle radius [m] (the lattice radius for sc/fcc; default: the generator's)")
    p.add_argument("--spread", type=float, default=None, metavar="S",
                   help="relative half-width of the uniform radius distribution, random shapes only "
                        f"(default: {d['spread']})")
    p.add_argument("--packing-fraction", type=_positive_float, default=None, dest="packing_fraction",
                   metavar="PHI",
                   help="target packing fraction, random shapes only (default: the densest of 0.60, 0.58, 0.56, "
                        "0.55 that packs without jamming)")
    p.add_argument("--bond-radius-ratio", type=_positive_float, default=None, dest="bond_radius_ratio",
                   metavar="RATIO",
                   help=f"bond radius / radius of the smaller particle (default: {d['bond_radius_ratio']})")
    p.add_argument("--E", type=_positive_float, default=None, dest="E", metavar="PA",
                   help=f"Young's modulus of the bonds [Pa] (default: {d['E']:g})")
    p.add_argument("--nu", type=float, default=None, metavar="NU",
                   help=f"Poisson ratio of the bonds (default: {d['nu']})")
    p.add_argument("--quiet", action="store_true", help="no progress output while generating")
    p.add_argument("--force", action="store_true", help=_FORCE_HELP)
    p.set_defaults(func=_cmd_generate)



def _add_info(sub) -> None:
    """The ``info`` command: a summary of a sample file or of the compilation cache."""
    p = sub.add_parser("info", help="print a summary of a sample file (or of the compilation cache)",
                       description="Print a summary of a sample file: counts, coordination, clusters, packing "
                                   "fraction, radii, extent and mass. With --cache, also (or, without a sample "
                                   "file, only) the compilation cache: directory, number of cached programs, size.")
    p.add_argument("sample", type=pathlib.Path, nargs="?", default=None, help="sample file (.h5) written by jaxbpm")
    p.add_argument("--cache", action="store_true",
                   help="print the compilation cache directory in effect (or the default one), its number of "
                        "cached programs and its size")
    p.set_defaults(func=_cmd_info, usage_error=p.error)



def _add_export_vtk(sub) -> None:
    """The ``export-vtk`` command: a sample file as VTK for ParaView."""
    p = sub.add_parser("export-vtk", help="export a sample file to VTK for ParaView",
                       description="Export a sample file to VTK: particles as points/vertices (radius, mass, "
                                   "coordination) and bonds as lines (bond_radius, material, length). The suffix "
                                   "of OUT picks the format: .vtu (XML, preferred) or .vtk (legacy).")
    p.add_argument("sample", type=pathlib.Path, help="sample file (.h5) written by jaxbpm")
    p.add_argument("out", type=pathlib.Path, help="VTK file to write (.vtu or .vtk)")
    p.add_argument("--force", action="store_true", help=_FORCE_HELP)
    p.set_defaults(func=_cmd_export_vtk)



def _add_demo(sub) -> None:
    """The ``demo`` command: :func:`run_demo`."""
    p = sub.add_parser("demo", help="run the demo (a sample: STE, DSM and DEM stiffness, a calibration, a chart)",
                       description="Run the demo: generate a random box sample, save it to OUT/demo_sample.h5, "
                                   "compute its stiffness by STE, DSM (two tolerances) and DEM, compare stiffness "
                                   "and cost, calibrate the bond modulus to a target Young's modulus with the "
                                   "multi-fidelity calibrator (checked by one DEM run) and write "
                                   "OUT/demo_results.json and the speed-against-accuracy chart "
                                   "OUT/demo_speed_accuracy.png.")
    p.add_argument("--out", type=pathlib.Path, default=pathlib.Path(_DEMO_DIR),
                   help=f"output directory (default: ./{_DEMO_DIR}); a folder that holds an earlier demo's files is "
                        "refused unless --force")
    p.add_argument("--n", type=_positive_int, default=2000, help="number of particles (default: 2000)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="random seed (default: 0)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.add_argument("--no-solve", action="store_true", dest="no_solve",
                   help="only generate and save the sample (skip the DEM/DSM comparison)")
    p.add_argument("--no-calibrate", action="store_true", dest="no_calibrate",
                   help="skip the calibration step")
    p.add_argument("--force", action="store_true",
                   help="replace the files of an earlier demo in --out (its other files are left alone)")
    p.set_defaults(func=_cmd_demo)

# commands whose options come from another module (it imports JAX): name -> one-line help, name -> loader
_LAZY_COMMANDS = {
    "convert": "convert a sample between file formats (HDF5, LAMMPS data, CSV, VTU; dump -> VTU series)",
    "params": "translate bond parameters between jaxbpm, PFC, LAMMPS, Yade and MUSEN",
    "calibrate": "calibrate the bond moduli of a sample to measured targets",
}
_LAZY_LOADERS = {"convert": ("jaxbpm.interop.cli", "add_parsers"), "params": ("jaxbpm.interop.cli", "add_parsers"),
                 "calibrate": ("jaxbpm._calibrate_cli", "add_parser")}


class _CommandParser(argparse.ArgumentParser):
    """A sub-command's parser; with ``populate`` set, its options are added on first use (parse or help)."""

    populate = None

    def _ready(self) -> None:
        populate, self.populate = self.populate, None
        if populate is not None:
            populate()

    def parse_known_args(self, args=None, namespace=None):
        self._ready()
        return super().parse_known_args(args, namespace)

    def format_usage(self):
        self._ready()
        return super().format_usage()

    def format_help(self):
        self._ready()
        return super().format_help()


class _Into:
    """Stands in for the sub-parsers of ``jaxbpm`` for a module's ``add_parser(s)``: ``add_parser(name, ...)``
    returns the parser already registered under ``name`` (description and epilog taken from the call)."""

    def __init__(self, parsers: dict[str, argparse.ArgumentParser]):
        self.parsers = parsers

    def add_parser(self, name, **kwargs):
        parser = self.parsers[name]
        for key in ("description", "epilog"):
            if key in kwargs:
                setattr(parser, key, kwargs[key])
        return parser


def _populate(parsers: dict[str, argparse.ArgumentParser], loader: tuple[str, str]) -> None:
    """Add the options of the commands ``loader`` defines (module, function) to their registered parsers."""
    import importlib

    module, function = loader
    before = {name: len(p._actions) for name, p in parsers.items()}
    getattr(importlib.import_module(module), function)(_Into(parsers))
    for name, parser in parsers.items():
        if len(parser._actions) > before[name]:  # filled by this loader
            parser.populate = None
            _add_cache_options(parser.add_argument_group("compilation cache"), argparse.SUPPRESS)


def _add_cache_options(parser, default) -> None:
    parser.add_argument("--no-cache", action="store_true", default=default, dest="no_cache",
                        help="do not turn on JAX's persistent compilation cache (default: on, so compiled programs "
                             "are reused by later runs)")
    parser.add_argument("--cache-dir", type=pathlib.Path, default=default, dest="cache_dir", metavar="DIR",
                        help="directory of the compilation cache (default: $JAXBPM_CACHE_DIR, else "
                             "~/.cache/jaxbpm/xla or the platform's cache folder)")


def _enable_cache(args: argparse.Namespace) -> None:
    """JAX's persistent compilation cache, on unless ``--no-cache``. A ``--cache-dir`` that cannot be used is an
    error; the default directory that cannot be used only a warning (the command runs without the cache)."""
    from jaxbpm._cache import enable_compilation_cache

    if args.no_cache:
        return
    try:
        enable_compilation_cache(args.cache_dir)
    except OSError as exc:
        if args.cache_dir is not None:
            raise
        print(f"warning: {exc}; running without the compilation cache (--no-cache skips it)", file=sys.stderr)


def _negative_values(argv: list[str]) -> list[str]:
    """``--option -1e8`` as ``--option=-1e8``: argparse takes a negative number in exponent form (or ``-inf``) for
    an option and reports "expected one argument"; joined, the value reaches the option's own check."""
    out = []
    for token in argv:
        if out and out[-1].startswith("--") and "=" not in out[-1] and token.startswith("-") and _is_number(token):
            out[-1] = f"{out[-1]}={token}"
        else:
            out.append(token)
    return out


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``jaxbpm`` command.

    Sample and file errors print ``error: <message>`` on stderr and return 2; argparse exits (``--help``,
    ``--version``, usage errors) raise :class:`SystemExit` as usual.

    Args:
      argv: the arguments (default ``sys.argv[1:]``).

    Returns:
      The exit code: 0 on success, 1 where a command reports a failure (e.g. a calibration that did not converge),
      2 on an error, 130 when interrupted.
    """
    parser = build_parser()
    args = parser.parse_args(_negative_values(sys.argv[1:] if argv is None else list(argv)))
    import jax

    jax.config.update("jax_enable_x64", True)
    if args.no_cache and args.cache_dir is not None:
        parser.error("--no-cache and --cache-dir exclude each other")
    try:
        _enable_cache(args)
        return args.func(args)
    except (JaxbpmError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
