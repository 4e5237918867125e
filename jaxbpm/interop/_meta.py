"""The ``# jaxbpm {...}`` metadata line the LAMMPS and CSV writers add (what their columns cannot hold), the
CRC-32 checksums they write, and the number format they share."""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import numbers
import pathlib
import re
import zlib

import numpy as np

from jaxbpm.errors import ConventionError, SampleError, SampleFileError
from jaxbpm.sample import Domain, Sample


META = "# jaxbpm "
N_COEFFS = 12  # Kr Ks Kt Kb Fcr Fcs Tct Tcb gamma_r gamma_s gamma_t gamma_b
BIG = 1.0e300  # LAMMPS thresholds for unbreakable bonds (LAMMPS needs finite numbers)


def exact_text(x) -> str:
    """The shortest decimal that reads back as the same float.

    Args:
      x: a real number.

    Returns:
      ``repr(float(x))``.
    """
    return repr(float(x))


def meta_of(sample: Sample, **extra) -> dict:
    """What a LAMMPS or CSV file's columns cannot hold of a sample: its materials, ``bond_contact`` and domain.

    Args:
      sample: the sample.
      **extra: more fields (e.g. ``normalize``, ``particles``).

    Returns:
      The metadata (JSON-serialisable), ``format = "jaxbpm-exchange"``.
    """
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
    if sample.dim == 2:
        out.update(dim=2, thickness=float(sample.thickness))
    out.update(extra)
    return out


def meta_line(meta: dict) -> str:
    """The ``# jaxbpm {...}`` comment line of the metadata (one line of compact JSON).

    Args:
      meta: from :func:`meta_of`.

    Returns:
      The line, without its end.
    """
    return META + json.dumps(meta, separators=(",", ":"))


def parse_meta(text: str, where: str) -> dict | None:
    """Read a ``# jaxbpm {...}`` line, its fields checked.

    Args:
      text: a line.
      where: ``file:line`` for messages.

    Returns:
      The metadata, or ``None`` for any other line.

    Raises:
      SampleFileError: unreadable JSON, another format, or a field of the wrong type.
    """
    if not text.startswith(META):
        return None
    try:
        meta = json.loads(text[len(META):])
    except (ValueError, RecursionError) as exc:
        raise SampleFileError(f"{where}: unreadable jaxbpm header comment ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != "jaxbpm-exchange":
        raise SampleFileError(f"{where}: the '# jaxbpm' header comment is not a jaxbpm exchange header")
    _check_meta(meta, where)
    return meta


def _is_number(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def _check_meta(meta: dict, where: str) -> None:
    """Every field the readers use has the type they expect (a damaged header is a named error, not a KeyError)."""
    def bad(field, expected):
        raise SampleFileError(f"{where}: the '# jaxbpm' header comment's {field!r} must be {expected}, got "
                              f"{json.dumps(meta.get(field.split('.')[0]))[:80]}")

    for field in ("bond_contact", "particle_material", "materials"):
        if field not in meta:
            raise SampleFileError(f"{where}: the '# jaxbpm' header comment lacks {field!r}")
    if not isinstance(meta["bond_contact"], str):
        bad("bond_contact", "a string")
    pm = meta["particle_material"]
    if not isinstance(pm, dict) or not all(isinstance(k, str) and _is_number(v) for k, v in pm.items()):
        bad("particle_material", "an object of numbers")
    mats = meta["materials"]
    names = ("E", "nu", "tensile_strength", "shear_strength")
    if not isinstance(mats, dict) or set(mats) != set(names) or not all(
            isinstance(mats[k], list) and mats[k] and all(_is_number(v) for v in mats[k]) for k in names):
        bad("materials", f"an object of non-empty number lists {list(names)}")
    if len({len(mats[k]) for k in names}) != 1:
        bad("materials", "lists of one length (one entry per material)")
    if meta.get("dim", 3) not in (2, 3) or isinstance(meta.get("dim"), bool):
        bad("dim", "2 or 3")
    d = meta.get("domain")
    if d is not None and not (isinstance(d, dict) and isinstance(d.get("kind"), str) and all(
            isinstance(d.get(k), list) and len(d[k]) == meta.get("dim", 3)
            and all(_is_number(v) and math.isfinite(v) for v in d[k]) for k in ("lo", "hi"))):
        bad("domain", f"null or an object with 'kind' and {meta.get('dim', 3)} finite 'lo' and 'hi' values")
    t = meta.get("thickness")
    if (t is None) != (meta.get("dim", 3) == 3) or (t is not None and not (_is_number(t) and math.isfinite(t)
                                                                          and t > 0)):
        bad("thickness", "a finite number > 0 with dim 2, absent with dim 3")
    if "normalize" in meta and not isinstance(meta["normalize"], bool):
        bad("normalize", "true or false")
    if "bonds_file" in meta and not (isinstance(meta["bonds_file"], str) and meta["bonds_file"]
                                     and "/" not in meta["bonds_file"] and "\\" not in meta["bonds_file"]):
        bad("bonds_file", "a file name")
    for field in ("particles", "bonds"):
        if field in meta and not (isinstance(meta[field], int) and not isinstance(meta[field], bool)
                                  and meta[field] >= 0):
            bad(field, "a whole number >= 0")


def domain_of(meta: dict | None):
    """The sample's domain recorded in the metadata.

    Args:
      meta: from :func:`parse_meta`, or ``None``.

    Returns:
      A :class:`~jaxbpm.sample.Domain`, or ``None`` when none is recorded.
    """
    d = None if meta is None else meta.get("domain")
    return None if d is None else Domain(d["kind"], tuple(d["lo"]), tuple(d["hi"]))


# ---------------------------------------------------------------------------------------------- checksums
def crc32(text: str) -> str:
    """The CRC-32 (zlib) of ``text`` encoded as UTF-8.

    Args:
      text: the checksummed text.

    Returns:
      8 lowercase hex digits.
    """
    return f"{zlib.crc32(text.encode('utf-8', 'surrogatepass')):08x}"


def without_line(text: str, index: int) -> str:
    """``text`` without one of its lines and that line's break.

    Args:
      text: the text.
      index: the line, from 0, as ``str.splitlines`` counts.

    Returns:
      The rest of the text.
    """
    parts = text.splitlines(keepends=True)
    return "".join(parts[:index] + parts[index + 1:])


def checksums(line: str, where: str, names: tuple[str, ...]) -> dict[str, str]:
    """Read the ``NAME=XXXXXXXX`` checksums of a checksum line.

    Args:
      line: the line.
      where: ``file:line`` for messages.
      names: the checksums it must hold, e.g. ``("crc32",)``.

    Returns:
      ``{name: 8 hex digits}``.

    Raises:
      SampleFileError: a checksum is missing or malformed (the line was damaged).
    """
    out = {}
    for name in names:
        m = re.search(rf"(?:^|\s){name}=(\S*)", line)
        if m is None or not re.fullmatch(r"[0-9a-f]{8}", m.group(1)):
            raise SampleFileError(f"{where}: malformed checksum {name} in {line.strip()!r} (expected {name}= and 8 "
                                  f"hex digits): the file is damaged, or was edited by hand")
        out[name] = m.group(1)
    return out


def verify(text: str, name: str, expected: str, path, where: str, how: str) -> None:
    """Check that ``text`` has the CRC-32 ``expected``.

    Args:
      text: the checksummed text.
      name: the checksum's name (``crc32``), for the message.
      expected: its recorded value.
      path: the file, for the message.
      where: where the checksum is written, for the message.
      how: how to accept an intended edit, for the message.

    Raises:
      SampleFileError: the text does not match.
    """
    got = crc32(text)
    if got != expected:
        raise SampleFileError(f"{path}: the content does not match its CRC-32 checksum ({name}={expected} on {where}; "
                              f"the file gives {got}): the file is damaged, or was edited after jaxbpm wrote it. To "
                              f"accept an intended edit, {how} (the file is then read as it is)")


def names_file(read):
    """Decorate a reader so that its content errors name the file.

    Args:
      read: ``read(path, ...)``.

    Returns:
      The reader, whose :class:`SampleError` (content that makes no valid sample) and :class:`ConventionError`
      (coefficients with no jaxbpm counterpart) start with the path unless they name it already.
    """
    @functools.wraps(read)
    def wrapper(path, *args, **kw):
        try:
            return read(path, *args, **kw)
        except (SampleError, ConventionError) as exc:
            if str(path) in str(exc):
                raise
            raise type(exc)(f"{path}: {exc}") from exc
    return wrapper


def read_text(path: pathlib.Path) -> str:
    """The text of ``path``, or a :class:`SampleFileError` saying that it is missing, a folder or not text.

    Args:
      path: the file.

    Returns:
      Its text (the platform's default encoding).

    Raises:
      SampleFileError: the file is missing, a directory or not decodable.
    """
    if not path.exists():
        raise SampleFileError(f"{path}: no such file")
    if path.is_dir():
        raise SampleFileError(f"{path}: is a directory, not a file")
    try:
        return path.read_text()
    except UnicodeDecodeError as exc:
        raise SampleFileError(f"{path}: not a text file ({exc})") from None
