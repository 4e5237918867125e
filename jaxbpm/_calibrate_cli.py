"""The ``jaxbpm calibrate`` command."""

from __future__ import annotations

import argparse
import json
import pathlib
import sys


def add_parser(sub) -> None:
    """Add the ``calibrate`` command to the sub-parsers of the ``jaxbpm`` command.

    Args:
      sub: the object ``argparse.ArgumentParser.add_subparsers`` returns.
    """
    p = sub.add_parser(
        "calibrate", help="calibrate the bond moduli of a sample to measured targets",
        description="Calibrate the bond parameters of a sample so that a uniaxial compression reproduces the "
                    "targets. Scalar targets come from --target-E / --target-K; vector targets (stress-strain "
                    "points), several parameters and calibrator options from --config FILE.json: "
                    '{"targets": [{"observable": "stress", "at": [...], "value": [...], "weight": 1}], '
                    '"parameters": [{"key": "bond_E", "index": 0, "bounds": [lo, hi]}], "options": {...}}. The '
                    'config may also set "method", "solver" and "tol"; --method, --solver and --tol given on the '
                    'command line override them.')
    p.add_argument("sample", type=pathlib.Path, help="sample file (.h5) written by jaxbpm")
    p.add_argument("--target-E", type=float, default=None, dest="target_E", metavar="PA",
                   help="target Young's modulus [Pa]")
    p.add_argument("--target-K", type=float, default=None, dest="target_K", metavar="N/M",
                   help="target stiffness [N/m]")
    p.add_argument("--config", type=pathlib.Path, default=None, help="JSON file with targets, parameters, options")
    p.add_argument("--method", default=None, choices=("auto", "adam", "surrogate", "closed-form"),
                   help="calibrator (default: auto = multi-fidelity, closed form where it applies)")
    p.add_argument("--solver", default=None, choices=("dsm", "ste", "dem"),
                   help="solver for adam/surrogate/closed-form (default: dsm)")
    p.add_argument("--model", default=None, choices=("dsm", "ste", "dem"), help=argparse.SUPPRESS)  # old --solver
    p.add_argument("--tol", type=float, default=None, help="relative tolerance on every target (default: 0.005 for stiffness, modulus and Poisson ratio "
                        "targets, the accuracy of the static solvers; else 0.05)")
    p.add_argument("--strain", type=float, default=0.002, help="compression strain (default: 0.002)")
    p.add_argument("--axis", type=int, default=2, choices=(0, 1, 2), help="loading axis (default: 2)")
    p.add_argument("--check", default=None, choices=("dsm", "ste", "dem"),
                   help="solve once at the answer with this solver and report its errors")
    p.add_argument("--no-shortcut", action="store_true", dest="no_shortcut",
                   help="do not replace Adam by the closed form where it applies")
    p.add_argument("--history", type=pathlib.Path, default=None, help="write the history to this HDF5 file")
    p.add_argument("--force", action="store_true",
                   help="replace an existing sample or record at --history or the lab report (never an input)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=run)


_DEFAULTS = {"method": "auto", "solver": "dsm", "tol": None}  # of the options a --config can also set (tol None:
# calibrate's default for the targets)


def _config(path: pathlib.Path) -> dict:
    """The calibration config in the JSON file ``path``; its old key ``"model"`` becomes ``"solver"`` (a
    deprecation message on stderr)."""
    from jaxbpm.calibrate import CalibrationError

    if not path.exists():
        raise CalibrationError(f"{path}: no such config file")
    try:
        cfg = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise CalibrationError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(cfg, dict):
        raise CalibrationError(f"{path}: the config must be a JSON object")
    unknown = set(cfg) - {"targets", "parameters", "options", "method", "solver", "model", "tol", "lab"}
    if unknown:
        raise CalibrationError(f"{path}: unknown config keys {sorted(unknown)}")
    if "model" in cfg:
        if "solver" in cfg:
            raise CalibrationError(f'{path}: give "solver" only ("model" is its deprecated name)')
        _deprecated(f'{path}: the config key "model" is deprecated and will be removed in the next release; '
                    'use "solver"')
        cfg["solver"] = cfg.pop("model")
    return cfg


def _deprecated(message: str) -> None:
    print(f"warning: {message}", file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    """Run ``jaxbpm calibrate`` (or, for a config with a ``"lab"`` object, the staged laboratory calibration).

    Args:
      args: the parsed command line.

    Returns:
      The exit status: 0 when every target is reached within the tolerance, else 1.

    Raises:
      CalibrationError: a bad config, no target, a bad calibrator option, or a calibration that fails (the
        ``jaxbpm`` command prints it and exits with 2).
    """
    from jaxbpm._outputs import check_outputs
    from jaxbpm.calibrate import CalibrationError, Parameter, Target, calibrate
    from jaxbpm.calibrate.dispatch import default_tol
    from jaxbpm.io import load_sample
    from jaxbpm.scenes import UniaxialCompression

    cfg = _config(args.config) if args.config is not None else {}
    if "lab" in cfg:
        return _run_lab(args, cfg)
    targets = []
    if args.target_E is not None:
        targets.append(Target("youngs_modulus", args.target_E))
    if args.target_K is not None:
        targets.append(Target("stiffness", args.target_K))
    for i, t in enumerate(cfg.get("targets", [])):
        if not isinstance(t, dict):
            raise CalibrationError(f"config targets[{i}] must be an object")
        try:
            targets.append(Target(**t))
        except TypeError as exc:
            raise CalibrationError(f"config targets[{i}]: {exc}") from None
    if not targets:
        raise CalibrationError("no target: give --target-E, --target-K or targets in --config")
    parameters = None
    if "parameters" in cfg:
        try:
            parameters = [Parameter(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in p.items()})
                          for p in cfg["parameters"]]
        except (TypeError, AttributeError) as exc:
            raise CalibrationError(f"config parameters: {exc}") from None
    options = cfg.get("options", {})
    if not isinstance(options, dict):
        raise CalibrationError("config options must be an object")
    runs_file = options.get("runs_file")
    check_outputs({"--history": args.history}, {"SAMPLE": args.sample, "--config": args.config}, force=args.force,
                  resumable={"runs_file": runs_file if isinstance(runs_file, (str, pathlib.Path)) else None})
    sample = load_sample(args.sample)
    scene = UniaxialCompression(axis=args.axis, strain=args.strain)
    # defaults < --config < options given on the command line (those default to None when not given)
    if args.model is not None:
        _deprecated("--model is deprecated and will be removed in the next release; use --solver")
        args.solver = args.model if args.solver is None else args.solver
    method, solver, tol = (getattr(args, key) if getattr(args, key) is not None else cfg.get(key, default)
                           for key, default in _DEFAULTS.items())
    print(f"calibrating {sample.n_particles} particles, {sample.n_bonds} bonds: method {method}, solver {solver}, "
          f"tol {100 * (default_tol(targets, method) if tol is None else tol):g} %", flush=True)
    try:
        result = calibrate(sample, scene, targets, method=method, solver=solver, parameters=parameters, tol=tol,
                           shortcut=not args.no_shortcut, check=args.check, progress=not args.quiet, **options)
    except TypeError as exc:
        raise CalibrationError(f"bad calibrator option: {exc}") from None
    print()
    print(result.table())
    if "check" in result.info:
        c = result.info["check"]
        print(f"check with {c['solver']}: largest error {100 * c['max_error']:.3f} % ({c['wall_time']:.2f} s)")
    if args.history is not None:
        print(f"wrote {result.save(args.history)}")
    return 0 if result.converged else 1


def _run_lab(args: argparse.Namespace, cfg: dict) -> int:
    """``--config`` with a ``"lab"`` object: the staged laboratory calibration (:func:`jaxbpm.calibrate.lab`)::

        {"lab": {"targets": {"E": 2.1e11, "nu": 0.17, "ucs": 2e9, "bts": 2.5e8, "flexural": 7.8e8},
                 "samples": {"ucs": "cylinder.h5", "bts": "disc.h5", "flexural": "beam.h5"},
                 "options": {"tol": 0.05}, "report": "lab.md"}}

    The positional sample serves every test that ``samples`` does not name."""
    from jaxbpm._outputs import check_outputs
    from jaxbpm.calibrate import CalibrationError, lab
    from jaxbpm.io import load_sample

    spec = cfg["lab"]
    extra = set(cfg) - {"lab"}
    if extra:
        raise CalibrationError(f"a lab config holds only the 'lab' object, not {sorted(extra)}")
    if not isinstance(spec, dict) or not isinstance(spec.get("targets"), dict):
        raise CalibrationError('config "lab" must be an object with "targets": {"E": ..., "ucs": ..., ...}')
    unknown = set(spec) - {"targets", "samples", "options", "report"}
    if unknown:
        raise CalibrationError(f"unknown keys in config 'lab': {sorted(unknown)}")
    paths = spec.get("samples", {})
    if not isinstance(paths, dict):
        raise CalibrationError('config lab "samples" must map tests to sample files')
    here = pathlib.Path(args.config).parent
    if not all(isinstance(v, (str, pathlib.Path)) for v in paths.values()):
        raise CalibrationError('config lab "samples" must map tests to sample files')
    report = here / spec["report"] if spec.get("report") else None
    inputs = {"SAMPLE": args.sample, "--config": args.config,
              **{f'lab sample "{k}"': here / v for k, v in paths.items()}}
    chart = None if report is None else report.with_suffix(".png")
    check_outputs({'lab "report"': report, 'lab "report" chart': chart}, inputs, force=args.force)
    default = load_sample(args.sample)
    samples = {k: load_sample(here / v) for k, v in paths.items()}
    for key in ("ucs", "bts", "flexural"):
        samples.setdefault(key, default)
    samples.setdefault("elastic", samples["ucs"])
    options = spec.get("options", {})
    if not isinstance(options, dict):
        raise CalibrationError('config lab "options" must be an object')
    try:
        result = lab(samples, spec["targets"], progress=not args.quiet, **options)
    except TypeError as exc:
        raise CalibrationError(f"bad lab option: {exc}") from None
    print()
    print(result.table())
    for key, why in result.unreached.items():
        print(f"not reached: {key}: {why}")
    if report is not None:
        print(f"wrote {result.report(report)}")
    return 0 if result.converged else 1
