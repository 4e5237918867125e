"""The ``# jaxbpm {...}`` metadata line the LAMMPS and CSV writers add (what their columns cannot hold),
and the number format they share."""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from jaxbpm.errors import SampleFileError
from jaxbpm.sample import Domain, Sample


_META = "# jaxbpm "
_N_COEFFS = 12  # Kr Ks Kt Kb Fcr Fcs Tct Tcb gamma_r gamma_s gamma_t gamma_b
_BIG = 1.0e300  # LAMMPS thresholds for unbreakable bonds (LAMMPS needs finite numbers)


def _r(x) -> str:
    """Shortest exact decimal of a float."""
    return repr(float(x))


def _meta(sample: Sample, **extra) -> dict:
    from jaxbpm._version import __version__

    pm = sample.particle_material
    m = sample.materials
    out = {"format": "jaxbpm-exchange", "version": 1, "jaxbpm": __version__, "bond_contact": sample.bond_contact,
           "particle_material": {f.name: float(getattr(pm, f.name)) for f in dataclasses.fields(pm)},
           "materials": {k: [float(v) for v in np.asarray(getattr(m, k))] for k in
                         ("E", "nu", "tensile_strength", "shear_strength")},
           "domain": None if sample.domain is None else
           {"kind": sample.domain.kind, "lo": list(map(float, sample.domain.lo)),
            "hi": list(map(float, sample.domain.hi))}}
    out.update(extra)
    return out


def _meta_line(meta: dict) -> str:
    return _META + json.dumps(meta, separators=(",", ":"))


def _parse_meta(text: str, where: str) -> dict | None:
    if not text.startswith(_META):
        return None
    try:
        meta = json.loads(text[len(_META):])
    except ValueError as exc:
        raise SampleFileError(f"{where}: unreadable jaxbpm header comment ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != "jaxbpm-exchange":
        raise SampleFileError(f"{where}: the '# jaxbpm' header comment is not a jaxbpm exchange header")
    return meta


def _domain(meta: dict | None):
    d = None if meta is None else meta.get("domain")
    return None if d is None else Domain(d["kind"], tuple(d["lo"]), tuple(d["hi"]))
