"""The ``convert`` and ``params`` sub-commands of ``jaxbpm`` (file formats and bond parameter conventions)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import pathlib
import sys
import warnings

import numpy as np

from jaxbpm.errors import ConventionError

__all__ = ["add_parsers"]


def _cmd_convert(args: argparse.Namespace) -> int:
    from jaxbpm._outputs import check_outputs
    from jaxbpm.interop import formats

    check_outputs(_companions({"OUT": args.output}), _companions({"IN": args.input, "--sample": args.sample}),
                  force=args.force)
    kw = {}
    if args.normalize:
        kw["normalize"] = True
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        written = formats.convert(args.input, args.output, sample=args.sample, format=args.format, **kw)
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
    for path in written[:3]:
        print(f"wrote {path}")
    if len(written) > 3:
        print(f"... and {len(written) - 3} more files")
    return 0


def _companions(paths: dict) -> dict:
    """``paths`` with the bonds file of each CSV sample (``<stem>_bonds.csv``, read and written with it)."""
    out = dict(paths)
    for label, path in paths.items():
        if path is not None and path.suffix.lower() == ".csv":
            out[f"{label} (its bonds file)"] = path.with_name(f"{path.stem}_bonds{path.suffix}")
    return out


def _parse_values(items: list[str]) -> dict[str, float]:
    values = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise ConventionError(f"parameters are NAME=VALUE, got {item!r}")
        try:
            values[name] = float(text)
        except ValueError:
            raise ConventionError(f"parameter {name}: {text!r} is not a number") from None
    return values


def _fmt(value) -> str:
    arr = np.asarray(value)
    return repr(float(arr)) if arr.size == 1 else str(arr.tolist())


def _cmd_params(args: argparse.Namespace) -> int:
    from jaxbpm.interop import conventions

    values = _parse_values(args.values)
    r1 = args.radius1
    r2 = args.radius2 if args.radius2 is not None else r1
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = conventions.convert(args.source, args.target, values, radius1=r1, radius2=r2, length=args.length,
                                  normalize=args.normalize, thickness=args.thickness)
        length = args.length if args.length is not None else r1 + r2
        bond = conventions.convert(args.source, "jaxbpm", values, radius1=r1, radius2=r2, length=args.length,
                                   thickness=args.thickness)
    fields = {f.name: getattr(out, f.name) for f in dataclasses.fields(out)
              if getattr(out, f.name) is not None}
    k = bond.stiffness(length)
    table = {"from": args.source, "to": args.target, "radius1": r1, "radius2": r2, "length": length,
             "parameters": {name: float(np.asarray(v)) for name, v in fields.items()},
             "stiffness": {"k_n": float(k.kn), "k_t": float(k.kt), "k_tw": float(k.ktw), "k_b": float(k.kb)},
             "warnings": [str(w.message) for w in caught]}
    if args.json:
        print(json.dumps(table, indent=2))
    else:
        print(f"{args.source} -> {args.target}  (R1 = {r1:g} m, R2 = {r2:g} m, L = {length:g} m)")
        for name, v in fields.items():
            print(f"  {name:<18} {_fmt(v)}")
        print(f"stiffness  k_n {float(k.kn):.6g} N/m  k_t {float(k.kt):.6g} N/m  k_tw {float(k.ktw):.6g} N m/rad  "
              f"k_b {float(k.kb):.6g} N m/rad")
        for w in caught:
            print(f"warning: {w.message}", file=sys.stderr)
    return 0


def add_parsers(sub) -> None:
    """Add the ``convert`` and ``params`` commands to the ``jaxbpm`` parser.

    Args:
      sub: the parser's sub-parsers (``argparse``'s ``add_subparsers()``).
    """
    from jaxbpm.interop._registry import CONVENTIONS, FORMATS, READERS  # (no JAX: --help answers at once)

    known = ", ".join(f"{ext} ({what})" for ext, what in FORMATS.items())
    p = sub.add_parser(
        "convert", help="convert a sample between file formats (HDF5, LAMMPS data, CSV, VTU; dump -> VTU series)",
        description=f"Convert IN to OUT, formats by suffix: {known}. LAMMPS data files carry bpm/rotational bond "
                    "coefficients (read them in LAMMPS with 'read_data FILE nocoeff' plus bond_coeff lines).")
    p.add_argument("input", type=pathlib.Path, help="file to read")
    p.add_argument("output", type=pathlib.Path, help="file to write")
    p.add_argument("--sample", type=pathlib.Path, default=None,
                   help="reference sample (radii, bonds) when IN is a LAMMPS dump")
    p.add_argument("--format", choices=sorted(READERS), default=None,
                   help="read IN as this format whatever its suffix: "
                        + "; ".join(f"{k}: {v}" for k, v in READERS.items()))
    p.add_argument("--normalize", action="store_true",
                   help="LAMMPS output: coefficients for bond_style bpm/rotational normalize yes")
    p.add_argument("--force", action="store_true",
                   help="replace an existing sample or record at OUT (never IN or the --sample file)")
    p.set_defaults(func=_cmd_convert)

    names = sorted(CONVENTIONS)
    docs = "; ".join(f"{n}: {CONVENTIONS[n]['doc']}" for n in names)
    p = sub.add_parser(
        "params", help="translate bond parameters between jaxbpm, PFC, LAMMPS, Yade and MUSEN",
        description="Translate one bond's parameters between conventions (exact where possible; warnings state "
                    f"the size of any difference). Parameters: {docs}.",
        epilog="example: jaxbpm params --from pfc --to jaxbpm emod=1e9 kratio=2.5 pb_rmul=1 pb_ten=5e6 pb_coh=8e6 "
               "--radius1 1e-3")
    p.add_argument("--from", dest="source", required=True, choices=names, help="convention of the given values")
    p.add_argument("--to", dest="target", required=True, choices=names, help="convention to translate to")
    p.add_argument("values", nargs="+", metavar="NAME=VALUE", help="parameters of the --from convention")
    p.add_argument("--radius1", type=float, required=True, metavar="R", help="radius of the first particle [m]")
    p.add_argument("--radius2", type=float, default=None, metavar="R",
                   help="radius of the second particle [m] (default: --radius1)")
    p.add_argument("--length", type=float, default=None, metavar="L",
                   help="initial centre distance [m] (default: R1 + R2)")
    p.add_argument("--normalize", action="store_true", help="LAMMPS target: for bpm/rotational normalize yes")
    p.add_argument("--thickness", type=float, default=None, metavar="T",
                   help="a 2D bond between discs of thickness T [m] (PFC2D, LAMMPS dimension 2: a 2 r_b x T "
                        "rectangular section; PFC2D's T is 1)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_cmd_params)
