"""Sample files (HDF5) and VTK export for visualisation.

:func:`save_sample` / :func:`load_sample` store a :class:`~jaxbpm.sample.Sample` in an HDF5 file (format
``"jaxbpm-sample"``, version :data:`FORMAT_VERSION`) and read it back exactly: every array leaf round-trips
bit for bit, and the loaded sample is rebuilt with :meth:`Sample.from_arrays`, so it is validated again.
:func:`export_vtk` (from :mod:`jaxbpm._vtk`) writes particles and bonds for ParaView (``.vtu`` XML or ``.vtk``
legacy) through meshio.

Both writers are atomic (:func:`atomic_write`, from :mod:`jaxbpm._atomic`): they write a temporary file in the
target's directory and rename it onto the target only once it is complete, so an error or a crash never leaves a
half-written file behind.

File layout (all quantities SI; every dataset carries a ``units`` attribute):

==============================  ===========  ==========  =============================================
name                            shape        units       meaning
==============================  ===========  ==========  =============================================
``/positions``                  ``[n, 3]``   m           particle centres (``[n, 2]``: a 2D sample)
``/radii``                      ``[n]``      m           particle radii
``/bonds``                      ``[nb, 2]``  1           particle indices of each bond (i < j), int32
``/bond_radius``                ``[nb]``     m           bond radius
``/bond_material``              ``[nb]``     1           material component of each bond, int32
``/types``                      ``[n]``      1           each particle's type, int32 (files without it:
                                                         every particle type 1)
``/materials/E``                ``[nm]``     Pa          bond Young's modulus per component
``/materials/nu``               ``[nm]``     1           bond Poisson ratio
``/materials/tensile_strength`` ``[nm]``     Pa          (``inf`` = unbreakable)
``/materials/shear_strength``   ``[nm]``     Pa          (``inf`` = unbreakable)
``/particle_material/*``        scalars      see attr    density (kg/m^3), E (Pa), nu, friction,
                                                         restitution (1)
``/derived/*``                  ...          see attr    mass, inertia, bond_length, bond_area, bond_I,
                                                         bond_J, coordination: for external readers;
                                                         recomputed on load and checked against these
==============================  ===========  ==========  =============================================

A file written before ``/types`` existed loads with every particle type 1 and verifies as before.

Root attributes: ``format``, ``format_version``, ``jaxbpm_version``, ``units`` (a note), ``bond_contact``,
``domain_kind`` / ``domain_lo`` / ``domain_hi`` [m] when the sample has a domain (absent otherwise), and
``thickness`` [m], the discs' thickness, for a two-dimensional sample (absent for spheres).

Checks on load. The file starts with a 512-byte HDF5 user block (HDF5 readers skip it) whose first line,
``jaxbpm-sample crc32=XXXXXXXX bytes=N``, holds the CRC-32 (zlib) and length of the rest of the file: ``load_sample``
compares them before HDF5 reads anything, so a damaged or cut file is an error (HDF5's own reader can fail in
unpredictable ways on a damaged file, even hang). Inside, every non-empty array carries a Fletcher-32 checksum
(HDF5's ``fletcher32`` filter), and the ``/derived`` group's attribute ``inputs_crc32`` is the CRC-32 of everything
the sample is built from (the input arrays, the material table, the particle material's scalars, ``bond_contact``
and the domain, in a fixed order), compared with the sample loaded; these cover files without the header (written
before it existed, or rewritten by other tools). An edit through h5py changes the file too: load it with
``load_sample(path, verify=False)`` (the sample is still validated) and save it again.
"""

from __future__ import annotations

import pathlib
import re
import zlib

import numpy as np

from jaxbpm._atomic import STALE_AFTER_S, atomic_write, check_writable, write_json  # noqa: F401 (re-exported)
from jaxbpm._vtk import export_vtk
from jaxbpm.errors import SampleError, SampleFileError
from jaxbpm.sample import Domain, Sample

__all__ = ["FORMAT", "FORMAT_VERSION", "save_sample", "load_sample", "export_vtk", "write_json", "atomic_write",
           "check_writable", "save_local_map", "export_local_map_vtk", "plot_local_map"]

FORMAT = "jaxbpm-sample"
"""Value of the ``format`` root attribute of a sample file."""

FORMAT_VERSION = 1
"""The (only) sample file format version this jaxbpm writes and reads."""

_UNITS_NOTE = ("SI units: lengths m, masses kg, moduli and strengths Pa, density kg/m^3; "
               "each dataset has a 'units' attribute ('1' = dimensionless or an index)")

# (name, units) of the datasets Sample.from_arrays needs; bonds and bond_material are int32.
_INPUTS = [("positions", "m"), ("radii", "m"), ("bonds", "1"), ("bond_radius", "m"), ("bond_material", "1")]
_MATERIALS = [("E", "Pa"), ("nu", "1"), ("tensile_strength", "Pa"), ("shear_strength", "Pa")]
_PARTICLE_MATERIAL = [("density", "kg/m^3"), ("E", "Pa"), ("nu", "1"), ("friction", "1"), ("restitution", "1")]
_DERIVED = [("mass", "kg"), ("inertia", "kg m^2"), ("bond_length", "m"), ("bond_area", "m^2"), ("bond_I", "m^4"),
            ("bond_J", "m^4")]
_DERIVED_ALL = _DERIVED + [("coordination", "1")]  # what /derived holds



# ---------------------------------------------------------------------------------------------- HDF5 sample files
def _dataset(group, name: str, data, units: str) -> None:
    # a Fletcher-32 checksum per chunk: a flipped byte is an error on load, not a silently different sample (empty
    # and scalar datasets cannot be chunked, and have nothing to flip)
    data = np.asarray(data)
    checked = data.ndim >= 1 and data.size > 0
    group.create_dataset(name, data=data, fletcher32=checked).attrs["units"] = units


def _write_inputs(f, sample: Sample) -> None:
    """The fields :meth:`Sample.from_arrays` needs, plus the file's metadata."""
    from jaxbpm._version import __version__

    f.attrs["format"] = FORMAT
    f.attrs["format_version"] = np.int64(FORMAT_VERSION)
    f.attrs["jaxbpm_version"] = __version__
    f.attrs["units"] = _UNITS_NOTE
    f.attrs["bond_contact"] = sample.bond_contact
    if sample.thickness is not None:
        f.attrs["thickness"] = np.float64(sample.thickness)
    if sample.domain is not None:
        f.attrs["domain_kind"] = str(sample.domain.kind)
        f.attrs["domain_lo"] = np.asarray(sample.domain.lo, dtype=np.float64)
        f.attrs["domain_hi"] = np.asarray(sample.domain.hi, dtype=np.float64)
    dtypes = {"bonds": np.int32, "bond_material": np.int32}
    for name, units in _INPUTS:
        _dataset(f, name, np.asarray(getattr(sample, name), dtype=dtypes.get(name, np.float64)), units)
    _dataset(f, "types", _types(sample), "1")
    mats = f.create_group("materials")
    mats.attrs["description"] = "bond material table, one entry per component (index = /bond_material)"
    for name, units in _MATERIALS:
        _dataset(mats, name, np.asarray(getattr(sample.materials, name), dtype=np.float64), units)
    pm = f.create_group("particle_material")
    for name, units in _PARTICLE_MATERIAL:
        _dataset(pm, name, np.float64(getattr(sample.particle_material, name)), units)


def _types(sample: Sample) -> np.ndarray:
    """The sample's particle types as int32 (type 1 where it has none)."""
    t = sample.types
    return np.ones(sample.n_particles, np.int32) if t is None else np.asarray(t, dtype=np.int32)


def _inputs_crc32(sample: Sample) -> int:
    """CRC-32 (zlib) of everything ``sample`` is built from, in a fixed order: ``positions``, ``radii`` (float64),
    ``bonds``, ``bond_material`` (int32), ``bond_radius``, the material table ``E``, ``nu``, ``tensile_strength``,
    ``shear_strength`` and the particle material's scalars (float64), each array preceded by its shape (int64),
    little-endian; then ``bond_contact`` and the domain (``kind``, ``lo``, ``hi``; ``none`` without one); then the
    particle ``types`` (int32) where any is not 1 (so files written before types existed keep their CRC); then the
    thickness (float64) of a two-dimensional sample."""
    crc = 0

    def add(arr, dtype):
        nonlocal crc
        arr = np.ascontiguousarray(np.asarray(arr), dtype=np.dtype(dtype).newbyteorder("<"))
        crc = zlib.crc32(np.asarray(arr.shape, "<i8").tobytes(), crc)
        crc = zlib.crc32(arr.tobytes(), crc)

    add(sample.positions, np.float64)
    add(sample.radii, np.float64)
    add(sample.bonds, np.int32)
    add(sample.bond_material, np.int32)
    add(sample.bond_radius, np.float64)
    for name, _ in _MATERIALS:
        add(getattr(sample.materials, name), np.float64)
    add([getattr(sample.particle_material, name) for name, _ in _PARTICLE_MATERIAL], np.float64)
    crc = zlib.crc32(str(sample.bond_contact).encode("utf-8", "surrogatepass"), crc)
    d = sample.domain
    crc = zlib.crc32(b"none" if d is None else str(d.kind).encode("utf-8", "surrogatepass"), crc)
    if d is not None:
        add([d.lo, d.hi], np.float64)
    types = _types(sample)
    if np.any(types != 1):
        add(types, np.int32)
    if sample.thickness is not None:
        add([sample.thickness], np.float64)
    return crc


def _write_derived(f, sample: Sample) -> None:
    """Derived per-particle and per-bond quantities, for readers other than jaxbpm, and the inputs' CRC-32 (all
    checked on load)."""
    g = f.create_group("derived")
    g.attrs["description"] = "computed from the other fields; jaxbpm recomputes these on load"
    g.attrs["inputs_crc32"] = np.int64(_inputs_crc32(sample))
    for name, units in _DERIVED_ALL:
        _dataset(g, name, _derived_value(sample, name), units)


def _derived_value(sample: Sample, name: str) -> np.ndarray:
    """The derived quantity ``name`` of :data:`_DERIVED_ALL` as the file stores it."""
    if name == "coordination":
        return np.asarray(sample.coordination(), dtype=np.int32)
    return np.asarray(getattr(sample, name), dtype=np.float64)


def save_sample(path, sample: Sample) -> pathlib.Path:
    """Write ``sample`` to the HDF5 file ``path`` atomically (see the module docstring for the layout).

    Args:
      path: the file to write (conventionally ``*.h5``); replaced if it exists. Its directory must exist.
      sample: a :class:`~jaxbpm.sample.Sample`.

    Returns:
      ``path`` as a :class:`pathlib.Path`.

    Raises:
      TypeError: ``sample`` is not a :class:`Sample`.
      OSError: the file cannot be written (the target is then left untouched).
    """
    import h5py

    if not isinstance(sample, Sample):
        raise TypeError(f"save_sample expects a jaxbpm Sample, got {type(sample).__name__}")

    def write(tmp: str) -> None:
        with h5py.File(tmp, "w", userblock_size=_USERBLOCK) as f:
            _write_inputs(f, sample)
            _write_derived(f, sample)
        with open(tmp, "r+b") as fh:  # the header: CRC-32 and length of what follows it
            crc, size = _crc_after_userblock(fh)
            fh.seek(0)
            fh.write(f"{_SEAL} crc32={crc:08x} bytes={size}\n".encode().ljust(_USERBLOCK, b"\0"))

    return atomic_write(path, write)


_USERBLOCK = 512  # bytes before the HDF5 data (an HDF5 user block): jaxbpm's header line
_SEAL = "jaxbpm-sample"


def _crc_after_userblock(fh) -> tuple[int, int]:
    """CRC-32 and length of the open file ``fh`` after its user block."""
    fh.seek(_USERBLOCK)
    crc, size = 0, 0
    while chunk := fh.read(1 << 24):
        crc, size = zlib.crc32(chunk, crc), size + len(chunk)
    return crc, size


def _check_seal(path: pathlib.Path) -> None:
    """The file against the CRC-32 and length in its header (files without the header are not checked here)."""
    with open(path, "rb") as fh:
        head = fh.read(_USERBLOCK)
        if not head.startswith(_SEAL.encode() + b" "):
            return
        m = re.fullmatch(rb"jaxbpm-sample crc32=([0-9a-f]{8}) bytes=([0-9]{1,20})", head.split(b"\n", 1)[0])
        if m is None or b"\n" not in head:
            raise SampleFileError(f"{path}: the file's header (its first line, {head[:60]!r}) is damaged")
        crc, size = _crc_after_userblock(fh)
    want_crc, want_size = int(m[1], 16), int(m[2])
    if size != want_size:
        how = "cut short" if size < want_size else "longer than written"
        raise SampleFileError(f"{path}: the file holds {size + _USERBLOCK} bytes, but {want_size + _USERBLOCK} were "
                              f"written (its header says so): the file is {how}; {_CHANGED}")
    if crc != want_crc:
        raise SampleFileError(f"{path}: the file does not match the CRC-32 in its header (crc32={want_crc:08x}, the "
                              f"file gives {crc:08x}): the file is damaged, or was changed after jaxbpm wrote it; "
                              f"{_CHANGED}")


_CHANGED = ("if the change was intended (an edit through h5py), load it with load_sample(path, verify=False) (the "
            "sample is still validated) and save it again")


def _attr_str(value) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    if isinstance(value, np.ndarray) and value.shape == ():
        return _attr_str(value[()])
    return str(value)


def _check_header(f, path: pathlib.Path) -> None:
    if "format" not in f.attrs:
        raise SampleFileError(f"{path}: not a jaxbpm sample file (the HDF5 file has no 'format' attribute)")
    fmt = _attr_str(f.attrs["format"])
    if fmt != FORMAT:
        raise SampleFileError(f"{path}: not a jaxbpm sample file (format is {fmt!r}, expected {FORMAT!r})")
    if "format_version" not in f.attrs:
        raise SampleFileError(f"{path}: missing field 'format_version' (root attribute)")
    version = f.attrs["format_version"]
    try:
        ok = int(version) == version
    except (TypeError, ValueError):
        ok = False
    if not ok or int(version) != FORMAT_VERSION:
        from jaxbpm._version import __version__

        raise SampleFileError(
            f"{path}: unsupported sample file format_version {_attr_str(version)} "
            f"(this jaxbpm {__version__} reads format_version {FORMAT_VERSION})")


_SIZE_SLACK = 1000  # a dataset may claim at most this many times the file's size (compressed data): more is damage


def _read(group, name: str, path: pathlib.Path, limit: int) -> np.ndarray:
    where = f"{group.name.rstrip('/')}/{name}"
    if name not in group:
        raise SampleFileError(f"{path}: missing field '{where}'")
    obj = group[name]
    if not hasattr(obj, "shape") or not hasattr(obj, "dtype"):
        raise SampleFileError(f"{path}: field '{where}' is not a dataset")
    nbytes = int(np.prod(obj.shape, dtype=np.float64) * obj.dtype.itemsize) if obj.shape is not None else 0
    if nbytes > limit:
        raise SampleFileError(f"{path}: field '{where}' claims shape {tuple(obj.shape)}, far more data than the file "
                              f"holds: the file is corrupt")
    try:
        return np.asarray(obj[()])
    except OSError as exc:  # a checksum that does not match, or unreadable storage
        raise SampleFileError(f"{path}: field '{where}' is corrupt (its checksum does not match, or it cannot be "
                              f"read: {exc})") from exc


def _thickness(f, path: pathlib.Path) -> float | None:
    """The root attribute ``thickness`` (a two-dimensional sample's discs), or ``None`` where the file has none."""
    if "thickness" not in f.attrs:
        return None
    t = np.asarray(f.attrs["thickness"])
    if t.shape != () or not np.issubdtype(t.dtype, np.floating):
        raise SampleFileError(f"{path}: the root attribute 'thickness' must be one number [m], got {t.tolist()!r}")
    return float(t)


def _read_inputs(f, path: pathlib.Path, limit: int) -> dict:
    """What :meth:`Sample.from_arrays` needs, read from the open file as plain NumPy values and strings."""
    _check_header(f, path)
    data = {name: _read(f, name, path, limit) for name, _ in _INPUTS}
    data["types"] = _read(f, "types", path, limit) if "types" in f else None  # (older files: every particle type 1)
    for group_name in ("materials", "particle_material"):
        if group_name not in f or not hasattr(f[group_name], "keys"):
            raise SampleFileError(f"{path}: missing field '/{group_name}' (group)")
    data["materials"] = {name: _read(f["materials"], name, path, limit) for name, _ in _MATERIALS}
    data["particle_material"] = {name: _read(f["particle_material"], name, path, limit)
                                 for name, _ in _PARTICLE_MATERIAL}
    for name, value in data["particle_material"].items():
        if value.shape != () or not (np.issubdtype(value.dtype, np.floating) or np.issubdtype(value.dtype, np.integer)):
            raise SampleFileError(f"{path}: field '/particle_material/{name}' must be one number, got shape "
                                  f"{value.shape} of {value.dtype}")
    if "bond_contact" not in f.attrs:
        raise SampleFileError(f"{path}: missing field 'bond_contact' (root attribute)")
    data["bond_contact"] = _attr_str(f.attrs["bond_contact"])
    data["thickness"] = _thickness(f, path)
    data["domain"] = None
    domain_keys = [k for k in ("domain_kind", "domain_lo", "domain_hi") if k in f.attrs]
    if domain_keys:
        missing = sorted({"domain_kind", "domain_lo", "domain_hi"} - set(domain_keys))
        if missing:
            raise SampleFileError(f"{path}: missing field '{missing[0]}' (root attribute; the domain is partial)")
        try:
            lo, hi = (np.asarray(f.attrs[k], dtype=np.float64) for k in ("domain_lo", "domain_hi"))
        except (TypeError, ValueError) as exc:
            raise SampleFileError(f"{path}: domain_lo and domain_hi must be numbers ({exc})") from None
        dim = data["positions"].shape[1] if data["positions"].ndim == 2 else 3
        if lo.shape != (dim,) or hi.shape != (dim,):
            raise SampleError(f"{path}: domain_lo and domain_hi must hold {dim} values (the positions' columns), got "
                              f"shapes {lo.shape}, {hi.shape}")
        data["domain"] = Domain(_attr_str(f.attrs["domain_kind"]), tuple(lo.tolist()), tuple(hi.tolist()))
    return data


def _read_derived(f, path: pathlib.Path, limit: int) -> dict | None:
    """The file's ``/derived`` quantities and ``inputs_crc32`` (``None`` without ``/derived``)."""
    if "derived" not in f:
        return None
    g = f["derived"]
    if not hasattr(g, "keys"):
        raise SampleFileError(f"{path}: '/derived' is not a group")
    out = {name: _read(g, name, path, limit) for name, _ in _DERIVED_ALL if name in g}
    if "inputs_crc32" in g.attrs:
        crc = np.asarray(g.attrs["inputs_crc32"])
        if crc.shape != () or not np.issubdtype(crc.dtype, np.integer):
            raise SampleFileError(f"{path}: the /derived attribute 'inputs_crc32' must be one whole number, got "
                                  f"{crc.tolist()!r}: the file is corrupt")
        out["inputs_crc32"] = int(crc)
    return out


def load_sample(path, *, verify: bool = True) -> Sample:
    """Read a sample written by :func:`save_sample` and validate it with :meth:`Sample.from_arrays`.

    With ``verify`` (the default), the file is first compared with the CRC-32 and length in its header (a damaged,
    cut or edited file is an error before HDF5 reads it), and derived quantities (mass, bond length, ...) are
    recomputed, not read, and checked against the file's ``/derived`` copies and ``inputs_crc32`` (for files without
    the header). Every array carries a Fletcher-32 checksum: a damaged byte is an error naming the field.
    ``verify=False`` reads a file changed on purpose (an edit through h5py) as it is: only the Fletcher-32 sums and
    the validation of the sample apply.

    Args:
      path: the HDF5 sample file.
      verify: compare the file with its checksums and its derived quantities (see above).

    Returns:
      The sample, validated.

    Raises:
      SampleFileError: the file is missing, is not an HDF5 file (or is corrupt), is not a jaxbpm sample, has an
        unsupported ``format_version``, or lacks a field (the message names the file and the problem).
      SampleError: the content is read but does not make a valid sample.
    """
    import h5py

    path = pathlib.Path(path)
    if not path.exists():
        raise SampleFileError(f"{path}: no such sample file")
    if path.is_dir():
        raise SampleFileError(f"{path}: is a directory, not a sample file")
    limit = _SIZE_SLACK * path.stat().st_size + (1 << 20)
    try:
        if verify:
            _check_seal(path)
        with h5py.File(path, "r") as f:
            data = _read_inputs(f, path, limit)
            derived = _read_derived(f, path, limit) if verify else None
    except (SampleFileError, SampleError):
        raise
    except Exception as exc:  # noqa: BLE001  h5py reports a damaged file as OSError, KeyError, ValueError, ...
        raise SampleFileError(f"{path}: not a readable HDF5 file, or corrupt ({type(exc).__name__}: {exc})") from exc
    try:
        sample = Sample.from_arrays(
            data["positions"], data["radii"], data["bonds"], data["bond_radius"],
            bond_material=data["bond_material"], materials=data["materials"],
            particle_material=data["particle_material"], bond_contact=data["bond_contact"], domain=data["domain"],
            types=data["types"], wide_bonds=True,  # (a file of a built sample: its bonds were accepted then)
            thickness=data["thickness"])
    except SampleError as exc:
        raise SampleError(f"{path}: {exc}") from exc
    if derived is not None:
        _check_derived(derived, path, sample)
    return sample


def _check_derived(stored_all: dict, path: pathlib.Path, sample: Sample) -> None:
    """The file's ``/derived`` quantities against the same ones recomputed from its inputs, and its
    ``inputs_crc32`` against the sample loaded: a mismatch means the inputs changed after the file was written (an
    edit, or damage the Fletcher-32 checksums cannot see)."""
    for name, _ in _DERIVED_ALL:
        if name not in stored_all:
            continue
        stored = stored_all[name]
        fresh = _derived_value(sample, name)
        if stored.shape != fresh.shape:
            raise SampleFileError(f"{path}: /derived/{name} has shape {stored.shape}, the sample's inputs give "
                                  f"{fresh.shape}: {_EDITED}")
        try:
            same = np.isclose(stored, fresh, rtol=1e-9, atol=0)
        except TypeError:
            raise SampleFileError(f"{path}: /derived/{name} holds {stored.dtype}, not numbers: {_EDITED}") from None
        bad = np.flatnonzero(~same.reshape(same.shape[0], -1).all(axis=1)) if same.size else np.zeros(0, int)
        if bad.size:
            i = int(bad[0])
            raise SampleFileError(
                f"{path}: /derived/{name}[{i}] is {stored[i].tolist()!r} in the file but {fresh[i].tolist()!r} from "
                f"its positions, radii and bonds ({bad.size} entries differ): {_EDITED}")
    if "inputs_crc32" in stored_all:
        crc = _inputs_crc32(sample)
        if stored_all["inputs_crc32"] != crc:
            raise SampleFileError(f"{path}: the sample read does not match the file's checksum (/derived attribute "
                                  f"inputs_crc32 = {stored_all['inputs_crc32']}, the data give {crc}): {_EDITED}")


_EDITED = ("the inputs changed after the file was written, or the file is damaged. If the change was intended, "
           "delete the /derived group (jaxbpm recomputes it) or load the file with load_sample(path, verify=False), "
           "and save the sample again")


# ---------------------------------------------------------------------------------------------------- STE map
def save_local_map(path, lmap) -> pathlib.Path:
    """Write a :class:`~jaxbpm.ste.LocalMap` to HDF5, atomically.

    Datasets ``positions`` [m], ``E`` [Pa], ``deviation`` [1], ``valid``; attributes ``format = "jaxbpm-ste-map"``,
    ``radius`` [m].

    Args:
      path: the target file.
      lmap: the local map.

    Returns:
      ``path`` as a :class:`pathlib.Path`.
    """
    import h5py

    def write(tmp):
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = "jaxbpm-ste-map"
            f.attrs["radius"] = lmap.radius
            for name, units in (("positions", "m"), ("E", "Pa"), ("deviation", "1"), ("valid", "1")):
                arr = np.asarray(getattr(lmap, name))
                ds = f.create_dataset(name, data=arr.astype(np.uint8) if arr.dtype == bool else arr)
                ds.attrs["units"] = units

    return atomic_write(path, write)


def export_local_map_vtk(path, sample, lmap) -> pathlib.Path:
    """Write the sample with a local stiffness map as point data, through :func:`export_vtk`.

    Args:
      path: ``*.vtu`` or ``*.vtk``.
      sample: the sample the map belongs to.
      lmap: the :class:`~jaxbpm.ste.LocalMap`; written as ``E_local [n, 3]``, ``deviation [n, 3]``, ``ste_valid``.

    Returns:
      ``path`` as a :class:`pathlib.Path`.
    """
    return export_vtk(path, sample, point_data={"E_local": lmap.E, "deviation": lmap.deviation,
                                                "ste_valid": lmap.valid})


def plot_local_map(path, lmap, *, direction: int = 2, slice_axis: int = 1, thickness: float | None = None):
    """Save a picture of a local stiffness map's deviation (Eq. 36, percent) in a slice through the sample.

    Written atomically, without pyplot or any global matplotlib state.

    Args:
      path: the picture; its suffix gives the format (PNG, SVG, PDF, ...).
      lmap: the :class:`~jaxbpm.ste.LocalMap`.
      direction: the stiffness direction shown (0, 1, 2 for x, y, z).
      slice_axis: the slice's normal, through the middle of the sample.
      thickness: the slice's thickness [m]; default two neighbourhood radii.

    Returns:
      ``path`` as a :class:`pathlib.Path`.
    """
    from matplotlib.figure import Figure

    pos = lmap.positions
    mid = 0.5 * (pos[:, slice_axis].min() + pos[:, slice_axis].max())
    t = 2.0 * lmap.radius if thickness is None else float(thickness)
    sel = (np.abs(pos[:, slice_axis] - mid) <= 0.5 * t) & np.isfinite(lmap.deviation[:, direction])
    axes = [k for k in range(3) if k != slice_axis]
    fig = Figure(figsize=(5, 4.5))
    fig.set_layout_engine("constrained")
    ax = fig.add_subplot()
    val = 100.0 * lmap.deviation[sel, direction]
    lim = float(np.nanmax(np.abs(val))) if val.size else 1.0
    sc = ax.scatter(pos[sel, axes[0]], pos[sel, axes[1]], c=val, cmap="coolwarm", vmin=-lim, vmax=lim, s=12)
    fig.colorbar(sc, ax=ax, label=f"deviation of E_{'xyz'[direction]} from the mean [%] (Eq. 36)")
    ax.set_xlabel(f"{'xyz'[axes[0]]} [m]")
    ax.set_ylabel(f"{'xyz'[axes[1]]} [m]")
    ax.set_aspect("equal")
    ax.set_title(f"STE local stiffness, slice normal to {'xyz'[slice_axis]}")
    from jaxbpm.plots import save

    return save(fig, path)
