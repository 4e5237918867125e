"""The checks of the arrays a :class:`~jaxbpm.sample.Sample` is built from, one function per input, each raising a
:class:`~jaxbpm.errors.SampleError` that names the problem and the offending indices (the steps of
:meth:`Sample.from_arrays <jaxbpm.sample.Sample.from_arrays>`)."""

from __future__ import annotations

import numpy as np

from jaxbpm._text import shown
from jaxbpm.errors import SampleError

__all__ = ["MAX_LISTED", "listed", "array", "float_array", "finite", "checked_positions", "checked_radii",
           "checked_bonds", "bond_lengths", "checked_bond_radius", "checked_bond_material", "checked_types"]

MAX_LISTED = 10  # how many offending indices an error message lists


def listed(idx) -> str:
    """Indices for an error message: the first :data:`MAX_LISTED`, and how many in all when there are more.

    Args:
      idx: integer indices.

    Returns:
      ``"[0, 3, 7]"`` or ``"[0, 1, ..., 9] ... (25 in all)"``.
    """
    idx = np.asarray(idx).tolist()
    more = f" ... ({len(idx)} in all)" if len(idx) > MAX_LISTED else ""
    return f"{idx[:MAX_LISTED]}{more}"


def array(name: str, x) -> np.ndarray:
    """``np.asarray(x)``, or a :class:`SampleError` naming ``name`` for what makes no array (ragged lists, ...).

    Args:
      name: the input's name, for the message.
      x: the input.

    Returns:
      ``x`` as a NumPy array.

    Raises:
      SampleError: ``x`` makes no array.
    """
    try:
        return np.asarray(x)
    except (TypeError, ValueError, OverflowError) as exc:
        raise SampleError(f"{name} must be an array of numbers, got {shown(x)} ({exc})") from None


def float_array(name: str, x) -> np.ndarray:
    """``x`` as a float64 array, or a :class:`SampleError` when it is not real numbers.

    Args:
      name: the input's name, for the message.
      x: the input (integers or floats).

    Returns:
      ``x`` as float64.

    Raises:
      SampleError: ``x`` makes no array, or not one of real numbers.
    """
    arr = array(name, x)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise SampleError(f"{name} must be a real numeric array, got dtype {arr.dtype}")
    return arr.astype(np.float64)


def finite(name: str, arr: np.ndarray) -> None:
    """Raise a :class:`SampleError` naming the rows of ``arr`` that hold NaN or inf.

    Args:
      name: the input's name, for the message.
      arr: a float array; its rows are the first axis.

    Raises:
      SampleError: some value is not finite.
    """
    bad = ~np.isfinite(arr)
    if bad.any():
        rows = np.flatnonzero(bad.reshape(arr.shape[0], -1).any(axis=1)) if arr.ndim else np.array([0])
        kind = "NaN" if np.isnan(arr).any() else "inf"
        raise SampleError(f"{name} contains {kind} values at indices {listed(rows)}")


def _positive_per_item(name: str, value, count: int, shape: str, where: str) -> np.ndarray:
    """``value`` as ``[count]`` float64 (a scalar repeated), finite and > 0; the messages say what ``name`` must
    (``shape``: "have shape [n] ...") and ``where`` the items at fault are."""
    arr = float_array(name, value)
    if arr.ndim == 0:
        arr = np.full(count, float(arr))
    if arr.shape != (count,):
        raise SampleError(f"{name} must {shape}, got {arr.shape}")
    finite(name, arr)
    bad = np.flatnonzero(arr <= 0)
    if bad.size:
        raise SampleError(f"{name} must be > 0; {where} {listed(bad)}")
    return arr


def checked_positions(positions) -> np.ndarray:
    """The particle centres, checked.

    Args:
      positions: ``[n, 3]`` sphere centres or ``[n, 2]`` disc centres (a two-dimensional sample) [m], ``n >= 1``.

    Returns:
      ``[n, 3]`` or ``[n, 2]`` float64.

    Raises:
      SampleError: wrong shape, no particles, or values that are not finite.
    """
    pos = float_array("positions", positions)
    if pos.ndim != 2 or pos.shape[1] not in (2, 3):
        raise SampleError(f"positions must have shape [n, 3] (spheres) or [n, 2] (discs of a two-dimensional "
                          f"sample), got {pos.shape}")
    if pos.shape[0] == 0:
        raise SampleError("positions: the sample has no particles")
    finite("positions", pos)
    return pos


def checked_radii(radii, n: int) -> np.ndarray:
    """The particle radii, checked: positive, and such that mass (r^3) and inertia (r^5) are finite and > 0.

    Args:
      radii: ``[n]`` or a scalar [m].
      n: the number of particles.

    Returns:
      ``[n]`` float64.

    Raises:
      SampleError: wrong shape, values not finite, not positive, or out of float64's range for the inertia.
    """
    rad = _positive_per_item("radii", radii, n, f"have shape [{n}] (one per particle)",
                             "non-positive radius at particles")
    with np.errstate(over="ignore", under="ignore"):
        bad = np.flatnonzero(~(np.isfinite(rad ** 5) & (rad ** 5 > 0)))
    if bad.size:
        raise SampleError(f"radii must lie where mass and inertia are finite and > 0 in float64 (about 1e-60 to "
                          f"1e60 m); bad radius {rad[bad[0]]:g} m at particles {listed(bad)}")
    return rad


def _integer_pairs(bonds) -> np.ndarray:
    """``bonds`` as an integer ``[nb, 2]`` array (whole floats accepted), empty inputs as ``[0, 2]``."""
    b = array("bonds", bonds)
    if b.size == 0:
        b = np.zeros((0, 2), dtype=np.int32)
    if b.ndim != 2 or b.shape[1] != 2:
        raise SampleError(f"bonds must have shape [nb, 2], got {b.shape}")
    if not np.issubdtype(b.dtype, np.integer):
        if np.issubdtype(b.dtype, np.floating) and np.all(np.isfinite(b)) and np.all(b == np.round(b)):
            b = b.astype(np.int64)
        else:
            raise SampleError(f"bonds must hold integer particle indices, got dtype {b.dtype}")
    return b


def _no_duplicates(b: np.ndarray, n: int) -> None:
    """Raise a :class:`SampleError` naming repeated pairs of the sorted bonds ``b [nb, 2]``."""
    key = b[:, 0].astype(np.int64) * n + b[:, 1]
    order = np.argsort(key, kind="stable")
    dup = order[1:][key[order][1:] == key[order][:-1]]
    if dup.size:
        first = order[np.searchsorted(key[order], key[dup[0]])]
        raise SampleError(
            f"duplicate bonds ((i, j) and (j, i) count as the same) at bonds {listed(np.sort(dup))}; "
            f"e.g. bond {dup[0]} repeats bond {first} = {b[dup[0]].tolist()}")


def checked_bonds(bonds, n: int) -> np.ndarray:
    """The bonded pairs, checked and each sorted (``i < j``).

    Args:
      bonds: ``[nb, 2]`` integer particle indices (whole floats accepted); the order within a pair does not matter.
      n: the number of particles.

    Returns:
      ``[nb, 2]`` int32 with ``i < j`` in each row, in the given order of the bonds.

    Raises:
      SampleError: wrong shape or type, missing particles, self-bonds or duplicate pairs.
    """
    b = _integer_pairs(bonds)
    bad = np.flatnonzero(((b < 0) | (b >= n)).any(axis=1))
    if bad.size:
        raise SampleError(
            f"bonds reference missing particles (valid indices are 0..{n - 1}); bad bonds {listed(bad)}, "
            f"e.g. bond {bad[0]} = {b[bad[0]].tolist()}")
    bad = np.flatnonzero(b[:, 0] == b[:, 1])
    if bad.size:
        raise SampleError(f"self-bonds (a particle bonded to itself) at bonds {listed(bad)}")
    b = np.sort(b, axis=1).astype(np.int32)
    if b.shape[0]:
        _no_duplicates(b, n)
    return b


def bond_lengths(pos: np.ndarray, rad: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The initial bond lengths, checked: not zero, not far beyond the particles' reach, and far longer than the
    float64 round-off of the positions they are differences of.

    Args:
      pos: ``[n, 3]`` (or ``[n, 2]``) checked positions [m].
      rad: ``[n]`` checked radii [m].
      b: ``[nb, 2]`` checked bonds.

    Returns:
      ``[nb]`` float64 lengths [m].

    Raises:
      SampleError: zero-length bonds, bonds over 1000 times their particles' radii long, or positions so far from
        the origin that float64 cannot resolve the bond lengths.
    """
    with np.errstate(over="ignore"):  # (a length that overflows is caught below as far too long)
        length = np.linalg.norm(pos[b[:, 1]] - pos[b[:, 0]], axis=1)
    bad = np.flatnonzero(length <= 1e-9 * np.max(rad))
    if bad.size:
        raise SampleError(f"zero-length bonds (coincident particles) at bonds {listed(bad)}")
    gap = length / (rad[b[:, 0]] + rad[b[:, 1]])
    bad = np.flatnonzero(gap > 1e3)
    if bad.size:
        raise SampleError(f"bonds must join neighbours: bonds {listed(bad)} are more than 1000 times the sum of "
                          f"their particles' radii long (e.g. bond {bad[0]}: {length[bad[0]]:.4g} m)")
    # the bond vectors are differences of positions: their float64 round-off (eps |x|) must stay far below
    # the bond lengths, or a sample far from the origin gets bonds of the wrong length
    if b.shape[0]:
        scale = np.maximum(np.abs(pos[b[:, 0]]).max(axis=1), np.abs(pos[b[:, 1]]).max(axis=1))
        rel = np.finfo(np.float64).eps * scale / length
        bad = np.flatnonzero(rel > 1e-9)
        if bad.size:
            raise SampleError(f"positions lie too far from the origin for their bond lengths in float64 "
                              f"(round-off {rel.max():.2g} of a bond length, at bonds {listed(bad)}): recentre "
                              "the sample (subtract its centre from the positions)")
    return length


def _ratio(bond_radius_ratio) -> float:
    """``bond_radius_ratio`` as a finite positive float, or a :class:`SampleError`."""
    try:
        if isinstance(bond_radius_ratio, (str, bytes, bool)):
            raise TypeError
        ratio = float(bond_radius_ratio)
    except (TypeError, ValueError, OverflowError):
        ratio = float("nan")
    if not np.isfinite(ratio) or ratio <= 0:
        raise SampleError(f"bond_radius_ratio must be finite and > 0, got {shown(bond_radius_ratio)}")
    return ratio


def checked_bond_radius(bond_radius, bond_radius_ratio, rad: np.ndarray, b: np.ndarray,
                        wide_bonds: bool = False) -> np.ndarray:
    """The bond radii, given or as a ratio of the smaller particle's radius, checked.

    Args:
      bond_radius: ``[nb]`` or scalar [m], or ``None``.
      bond_radius_ratio: a number, or ``None``; exactly one of the two is given.
      rad: ``[n]`` checked radii [m].
      b: ``[nb, 2]`` checked bonds.
      wide_bonds: allow bonds wider than the smaller of their two particles (ratio above 1).

    Returns:
      ``[nb]`` float64 bond radii [m].

    Raises:
      SampleError: both or neither given, a bad ratio, wrong shape, values not finite and positive, or (without
        ``wide_bonds``) a bond radius above the smaller particle's radius.
    """
    if (bond_radius is None) == (bond_radius_ratio is None):
        raise SampleError("give exactly one of bond_radius and bond_radius_ratio")
    smaller = np.minimum(rad[b[:, 0]], rad[b[:, 1]])
    if bond_radius_ratio is not None:
        ratio = _ratio(bond_radius_ratio)
        if ratio > 1.0 + _WIDE_TOL and not wide_bonds and len(b):
            raise SampleError(f"bond_radius_ratio {shown(bond_radius_ratio)} > 1: bonds wider than the smaller of "
                              "their particles (the ratio is r_b / min(R1, R2), usually 0.5 to 1); pass "
                              "wide_bonds=True to allow them")
        return ratio * smaller
    nb = b.shape[0]
    rb = _positive_per_item("bond_radius", bond_radius, nb, f"be a scalar or have shape [{nb}]",
                            "non-positive at bonds")
    wide = np.flatnonzero(rb > smaller * (1.0 + _WIDE_TOL))
    if len(wide) and not wide_bonds:
        k = wide[np.argmax(rb[wide] / smaller[wide])]
        raise SampleError(f"bond_radius above the smaller particle's radius at bonds {listed(wide)} (bond {k}: "
                          f"{rb[k]:.6g} m, ratio {rb[k] / smaller[k]:.6g} to {smaller[k]:.6g} m); pass "
                          "wide_bonds=True to allow bonds wider than their particles")
    return rb


_WIDE_TOL = 1e-9  # a ratio of 1 computed through another code's convention may come out a rounding above it


def checked_bond_material(bond_material, nb: int, n_materials: int) -> np.ndarray:
    """The material component of each bond, checked against the table's size.

    Args:
      bond_material: ``[nb]`` or scalar integer component indices, or ``None`` (all 0).
      nb: the number of bonds.
      n_materials: the number of components in the material table.

    Returns:
      ``[nb]`` int32.

    Raises:
      SampleError: wrong shape or type, or an index outside the table.
    """
    if bond_material is None:
        bm = np.zeros(nb, dtype=np.int32)
    else:
        bm = array("bond_material", bond_material)
        if bm.ndim == 0:
            bm = np.full(nb, bm)
        if bm.shape != (nb,):
            raise SampleError(f"bond_material must have shape [{nb}], got {bm.shape}")
        if not np.issubdtype(bm.dtype, np.integer):
            raise SampleError(f"bond_material must hold integer component indices, got dtype {bm.dtype}")
        bm = bm.astype(np.int32)
    bad = np.flatnonzero((bm < 0) | (bm >= n_materials))
    if bad.size:
        raise SampleError(
            f"unknown material index (the table has {n_materials} components, 0..{n_materials - 1}) at bonds "
            f"{listed(bad)}, e.g. index {bm[bad[0]]}")
    return bm


def checked_types(types, n: int) -> np.ndarray:
    """The integer type of each particle (LAMMPS atom types, another code's material or group column).

    Args:
      types: ``[n]`` or scalar whole numbers >= 0 (floats that are whole numbers are accepted, as text files give
        them), or ``None`` (every particle type 1, LAMMPS's first atom type).
      n: the number of particles.

    Returns:
      ``[n]`` int32.

    Raises:
      SampleError: wrong shape, booleans, numbers that are not whole, or types below 0 or beyond int32.
    """
    if types is None:
        return np.ones(n, dtype=np.int32)
    t = array("types", types)
    if t.ndim == 0:
        t = np.full(n, t)
    if t.shape != (n,):
        raise SampleError(f"types must have shape [{n}] (one per particle), got {t.shape}")
    if t.dtype == bool or not (np.issubdtype(t.dtype, np.integer) or np.issubdtype(t.dtype, np.floating)):
        raise SampleError(f"types must hold whole numbers (one per particle), got dtype {t.dtype}")
    if np.issubdtype(t.dtype, np.floating):
        bad = np.flatnonzero(~np.isfinite(t) | (t != np.round(t)))
        if bad.size:
            raise SampleError(f"types must be whole numbers; not at particles {listed(bad)}, e.g. {t[bad[0]]!r}")
    bad = np.flatnonzero((t < 0) | (t > np.iinfo(np.int32).max))
    if bad.size:
        raise SampleError(f"types must lie in 0..{np.iinfo(np.int32).max}; not at particles {listed(bad)}, "
                          f"e.g. {t[bad[0]]!r}")
    return t.astype(np.int32)
