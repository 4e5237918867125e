"""Two-dimensional samples: discs in the x-y plane (positions ``[n, 2]``), bonded at their contacts.

* :func:`lattice2d` builds a square (``"square"``) or hexagonal (``"hex"``) lattice of equal touching discs, bonded to
  their nearest neighbours (``generate.lattice("square", (nx, ny))`` calls it).
* :func:`disc_packing` fills a rectangle, a disc or a beam with polydisperse discs: stratified random insertion, then
  overlap removal by relaxation on the host (NumPy and a k-d tree; the 2D problem is small enough not to need the
  jit-compiled FIRE of the 3D packings), then a bond between every pair closer than a small surface gap.

Both return a validated :class:`~jaxbpm.sample.Sample` of :attr:`~jaxbpm.sample.Sample.dim` 2 whose discs have the
``thickness`` given (default 1 m, PFC2D's unit thickness).
"""

from __future__ import annotations

import numpy as np

from jaxbpm._spatial import morton_order
from jaxbpm.errors import SampleError
from jaxbpm.sample import Domain, Sample

__all__ = ["lattice2d", "disc_packing", "DISC_SHAPES", "LATTICES_2D"]

LATTICES_2D = ("square", "hex")
"""The kinds of :func:`lattice2d`."""

DISC_SHAPES = ("rectangle", "disc", "beam")
"""The shapes :func:`disc_packing` fills."""

_DEFAULT_ASPECT = {"rectangle": (1.0, 1.0), "beam": (4.0, 1.0), "disc": None}
_SQUARE_OFFSETS = np.array([[1, 0], [0, 1]])
# hexagonal lattice on a skewed grid: site (i, j) at (i + j / 2, j sqrt(3) / 2) * 2 R; neighbours (1, 0), (0, 1),
# (-1, 1)
_HEX_OFFSETS = np.array([[1, 0], [0, 1], [-1, 1]])


def lattice2d(kind: str, cells, radius: float = 1e-3, *, bond_radius_ratio: float = 0.5, **sample_kw) -> Sample:
    """A regular lattice of equal touching discs in the x-y plane, bonded between nearest neighbours.

    Args:
      kind: ``"square"``: discs at ``(i, j) * 2 radius`` for ``i < nx``, ``j < ny`` (up to 4 bonds each).
        ``"hex"``: rows of ``nx`` discs, ``ny`` rows ``sqrt(3) radius`` apart, every other row shifted by ``radius``
        (up to 6 bonds each).
      cells: ``(nx, ny)``, each >= 1: discs per row and rows.
      radius: disc radius [m].
      bond_radius_ratio: bond radius / disc radius.
      **sample_kw: forwarded to :meth:`Sample.from_arrays` (``thickness``, ``materials``, ``density``, ...).

    Returns:
      A two-dimensional :class:`Sample` whose ``domain`` is the rectangle enclosing the discs; every bond has length
      ``2 radius``.

    Raises:
      SampleError: an unknown kind, bad cells or radius, or a keyword the generator sets itself.
    """
    _check_sample_kw(sample_kw)
    kind = str(kind).lower()
    if kind not in LATTICES_2D:
        raise SampleError(f"lattice: a two-dimensional kind must be one of {LATTICES_2D}, got {kind!r}")
    nx, ny = _cells(cells)
    radius = _positive("radius", radius)
    ij = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij"), axis=-1).reshape(-1, 2)
    if kind == "square":
        bonds = _pairs(ij, _SQUARE_OFFSETS, (nx, ny))
        xy = ij * 2.0 * radius
    else:  # rows shifted alternately: skewed index i' = i - floor(j / 2) makes the neighbours fixed offsets
        skew = np.stack([ij[:, 0] - ij[:, 1] // 2, ij[:, 1]], axis=1)
        bonds = _pairs(skew - skew.min(axis=0), _HEX_OFFSETS, None)
        xy = np.stack([2.0 * ij[:, 0] + (ij[:, 1] % 2), np.sqrt(3.0) * ij[:, 1]], axis=1) * radius
    hi = xy.max(axis=0) + radius
    domain = Domain("box", (-radius, -radius), tuple(float(v) for v in hi))
    return _build(xy.astype(np.float64), np.full(len(xy), radius), bonds, domain, bond_radius_ratio, sample_kw)


def _pairs(ij: np.ndarray, offsets: np.ndarray, dims) -> np.ndarray:
    """Bonds ``[nb, 2]`` (i < j, sorted) between sites ``ij [n, 2]`` (integer coordinates) that differ by one of
    ``offsets``."""
    dims = ij.max(axis=0) + 1 if dims is None else np.asarray(dims)
    lookup = np.full(tuple(dims), -1, dtype=np.int64)
    lookup[tuple(ij.T)] = np.arange(len(ij))
    pairs = []
    for off in offsets:
        nb = ij + off
        inside = np.all((nb >= 0) & (nb < dims), axis=1)
        j = np.full(len(ij), -1, dtype=np.int64)
        j[inside] = lookup[tuple(nb[inside].T)]
        keep = j >= 0
        pairs.append(np.stack([np.flatnonzero(keep), j[keep]], axis=1))
    return _sorted(np.concatenate(pairs))


def _sorted(pairs: np.ndarray) -> np.ndarray:
    pairs = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))].astype(np.int32)


# ----------------------------------------------------------------------------------------------- random packing
_PHI_BULK, _WALL_LOSS = 0.82, 0.25  # the default packing fraction: _PHI_BULK - _WALL_LOSS * perimeter / area
_RELAX = 0.6  # share of each overlap removed per relaxation sweep (split between the two discs)


def disc_packing(n: int, shape: str = "rectangle", *, mean_radius: float = 1e-3, radius_spread: float = 0.25,
                 aspect=None, packing_fraction: float | None = None, overlap_tol: float = 1e-3, bond_gap: float = 0.05,
                 bond_radius_ratio: float = 0.5, seed: int = 0, max_sweeps: int = 20_000, **sample_kw) -> Sample:
    """A dense random packing of polydisperse discs filling a rectangle, a disc or a beam, bonded at contacts.

    Radii are ``mean_radius * (1 + radius_spread * u)`` with ``u`` uniform in ``[-1, 1]`` (the default spread 0.25
    gives PFC's usual ratio of largest to smallest radius, about 1.66; equal discs would order into a hexagonal
    crystal). The domain's area is the discs' total area over ``packing_fraction``; its lower-left corner is the
    origin: a rectangle of edge ratio ``aspect = (ax, ay)`` (default ``(1, 1)``; a beam: ``(4, 1)``), or a disc
    (``aspect`` not used) centred in its bounding square.

    Centres are inserted at random inside the domain (one per randomly drawn cell of a grid of about a disc's size),
    then overlaps are removed by sweeps that push every overlapping pair apart along its axis by ``0.6`` times the
    overlap (shared equally) and bring discs that poke out of the boundary back in, until the largest overlap
    (pairs and boundary) is below ``overlap_tol * mean_radius``. Finally every pair with surface gap below
    ``bond_gap * mean_radius`` is bonded. Particles are numbered along a Morton curve.

    Args:
      n: number of discs (>= 1).
      shape: ``"rectangle"``, ``"disc"`` or ``"beam"``.
      mean_radius: mean disc radius [m].
      radius_spread: relative half-width of the uniform radius distribution, in ``[0, 1)``.
      aspect: ``(ax, ay)`` edge ratios of a rectangle or beam.
      packing_fraction: area fraction of the domain, in ``(0, 0.86)`` (polydisperse discs jam near 0.84; walls pack
        loosely, so small samples jam lower). ``None`` (default): ``0.82 - 0.25 P / A`` (``P / A``: the domain's
        perimeter over its area, lengths in mean radii), which stays clear of jamming: 0.80 for a square of 500
        discs, 0.77 for a beam of 150.
      overlap_tol: largest accepted overlap relative to ``mean_radius``.
      bond_gap: bonding distance (surface gap) relative to ``mean_radius``.
      bond_radius_ratio: bond radius / radius of the smaller disc of the pair.
      seed: seed of the NumPy generator (the result is deterministic).
      max_sweeps: relaxation sweep budget.
      **sample_kw: forwarded to :meth:`Sample.from_arrays` (``thickness``, ``materials``, ``density``, ...).

    Returns:
      A two-dimensional :class:`Sample` with ``domain`` set (``"box"``: the rectangle; ``"cylinder"``: the disc).

    Raises:
      SampleError: bad arguments, or overlaps left after ``max_sweeps`` (a ``packing_fraction`` too high for the
        domain).
    """
    _check_sample_kw(sample_kw)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise SampleError(f"n must be an integer >= 1, got {n!r}")
    shape = str(shape).lower()
    if shape not in DISC_SHAPES:
        raise SampleError(f"disc_packing: shape must be one of {DISC_SHAPES}, got {shape!r}")
    mean_radius = _positive("mean_radius", mean_radius)
    spread = float(radius_spread)
    if not 0 <= spread < 1:
        raise SampleError(f"radius_spread must lie in [0, 1), got {radius_spread!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SampleError(f"seed must be an integer >= 0, got {seed!r}")
    rng = np.random.default_rng(int(seed))
    radii = 1.0 + spread * rng.uniform(-1.0, 1.0, int(n))  # in mean radii
    solid = float(np.sum(np.pi * radii**2))
    if packing_fraction is None:
        phi = _PHI_BULK
        for _ in range(3):  # the fraction sets the domain, the domain's perimeter the fraction
            size = _domain_size(shape, aspect, solid / phi, float(radii.max()))
            perimeter = np.pi * size[0] if shape == "disc" else 2.0 * (size[0] + size[1])
            phi = _PHI_BULK - _WALL_LOSS * perimeter * phi / solid
    else:
        phi = _positive("packing_fraction", packing_fraction)
        if phi >= 0.86:
            raise SampleError(f"packing_fraction must be < 0.86 (random disc packings jam near 0.84), got {phi}")
    size = _domain_size(shape, aspect, solid / phi, float(radii.max()))
    x = _insert(rng, shape, size, radii)
    x = _relax(x, radii, shape, size, _positive("overlap_tol", overlap_tol), int(max_sweeps))
    order = morton_order(x)
    positions, radii = x[order] * mean_radius, radii[order] * mean_radius
    gap = float(bond_gap)
    if not (np.isfinite(gap) and gap >= 0):
        raise SampleError(f"bond_gap must be finite and >= 0, got {bond_gap!r}")
    bonds = contact_pairs(positions, radii, gap * mean_radius)
    domain = Domain("cylinder" if shape == "disc" else "box", (0.0, 0.0), tuple(float(s * mean_radius) for s in size))
    return _build(positions, radii, bonds, domain, bond_radius_ratio, sample_kw)


def _domain_size(shape: str, aspect, area: float, r_max: float) -> tuple[float, float]:
    """The bounding box ``(width, height)`` of a domain of ``area`` (mean-radius units)."""
    if shape == "disc":
        d = 2.0 * np.sqrt(area / np.pi)
        size = (d, d)
    else:
        a = _DEFAULT_ASPECT[shape] if aspect is None else aspect
        a = np.asarray(a, dtype=np.float64) if np.ndim(a) == 1 else np.array([np.nan])
        if a.shape != (2,) or not np.all(np.isfinite(a) & (a > 0)):
            raise SampleError(f"aspect of a {shape} must be two positive edge ratios (ax, ay), got {aspect!r}")
        size = tuple((a * np.sqrt(area / np.prod(a))).tolist())
    if min(size) <= 2.0 * r_max:
        raise SampleError(f"the {shape} ({min(size) / 2:.3g} mean radii across) is too thin for the largest disc; "
                          "use more discs or a less elongated aspect")
    return size


def _insert(rng, shape: str, size, radii) -> np.ndarray:
    """Random centres ``[n, 2]`` inside the domain shrunk by the largest radius, one per randomly drawn grid cell."""
    n, r_max = len(radii), float(radii.max())
    inner = np.asarray(size) - 2.0 * r_max
    h = np.sqrt(float(np.prod(inner)) * (np.pi / 4.0 if shape == "disc" else 1.0) / n)
    big = size[0] / 2.0
    while True:
        m = np.maximum(np.floor(inner / h).astype(np.int64), 1)
        ij = np.stack(np.meshgrid(np.arange(m[0]), np.arange(m[1]), indexing="ij"), axis=-1).reshape(-1, 2)
        centres = (ij + 0.5) / m * inner + r_max
        cells = np.arange(len(centres))
        if shape == "disc":
            cells = np.flatnonzero(np.hypot(*(centres - big).T) <= big - r_max)
        if len(cells) >= n:
            break
        h *= 0.95
    return centres[rng.choice(cells, n, replace=False)] + rng.uniform(-0.5, 0.5, (n, 2)) * (inner / m)


def _relax(x, radii, shape: str, size, tol: float, max_sweeps: int) -> np.ndarray:
    """``x`` with the overlaps (pairs and boundary) removed to below ``tol`` (see :func:`disc_packing`)."""
    from scipy.spatial import cKDTree

    skin = 0.5
    reach = 2.0 * float(radii.max()) + skin
    pairs, anchor = None, None
    for _ in range(max_sweeps):
        if pairs is None or np.max(np.abs(x - anchor)) > 0.5 * skin:
            pairs, anchor = cKDTree(x).query_pairs(reach, output_type="ndarray"), x.copy()
        x, boundary = _inside(x, radii, shape, size)
        i, j = pairs[:, 0], pairs[:, 1]
        d = x[j] - x[i]
        dist = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)
        overlap = np.maximum(radii[i] + radii[j] - dist, 0.0)
        worst = max(float(overlap.max(initial=0.0)), boundary)
        if worst < tol:
            return x
        push = (0.5 * _RELAX * overlap / dist)[:, None] * d
        move = np.zeros_like(x)
        np.add.at(move, i, -push)
        np.add.at(move, j, push)
        x = x + move
    raise SampleError(f"disc_packing: overlaps of {worst:.3g} mean radii remain after {max_sweeps} sweeps: the "
                      "packing_fraction is too high for this domain; lower it")


def _inside(x, radii, shape: str, size) -> tuple[np.ndarray, float]:
    """``x`` with every disc moved inside the domain, and the largest distance one poked out."""
    if shape == "disc":
        big = size[0] / 2.0
        d = x - big
        rho = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)
        out = np.maximum(rho + radii - big, 0.0)
        return x - d * (out / rho)[:, None], float(out.max())
    lo, hi = radii[:, None], np.asarray(size)[None, :] - radii[:, None]
    clipped = np.clip(x, lo, hi)
    return clipped, float(np.max(np.abs(clipped - x)))


def contact_pairs(positions, radii, gap: float) -> np.ndarray:
    """Pairs of discs (or spheres) whose surface gap ``|x_j - x_i| - r_i - r_j`` is below ``gap``.

    Args:
      positions: ``[n, 2]`` (or ``[n, 3]``) centres [m].
      radii: ``[n]`` radii [m].
      gap: largest surface gap of a bonded pair [m] (overlapping pairs, negative gaps, are included).

    Returns:
      ``[nb, 2]`` int32 particle indices, ``i < j``, sorted lexicographically.

    Raises:
      SampleError: wrong shapes, or a gap that is not finite.
    """
    from scipy.spatial import cKDTree

    pos = np.asarray(positions, dtype=np.float64)
    rad = np.asarray(radii, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] not in (2, 3) or rad.shape != (pos.shape[0],):
        raise SampleError(f"bond_pairs: need positions [n, 3] (or [n, 2]) and radii [n], got {pos.shape} and "
                          f"{rad.shape}")
    gap = float(gap)
    if not np.isfinite(gap):
        raise SampleError(f"bond_pairs: gap must be finite, got {gap}")
    none = np.zeros((0, 2), dtype=np.int32)
    reach = 2.0 * float(rad.max(initial=0.0)) + gap
    if pos.shape[0] < 2 or reach <= 0:
        return none
    pairs = cKDTree(pos).query_pairs(r=reach, output_type="ndarray")
    if pairs.size == 0:
        return none
    i, j = pairs[:, 0], pairs[:, 1]
    dist = np.linalg.norm(pos[j] - pos[i], axis=1)
    return _sorted(pairs[dist - rad[i] - rad[j] < gap])


def _cells(cells) -> tuple[int, int]:
    try:
        out = tuple(int(c) for c in cells)
        ok = len(out) == 2 and all(c == float(v) for c, v in zip(out, cells))
    except (TypeError, ValueError):
        ok = False
    if not ok or min(out) < 1:
        raise SampleError(f"lattice: a two-dimensional lattice's cells must be two integers >= 1 (nx, ny), got "
                          f"{cells!r}")
    return out


def _positive(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SampleError(f"{name} must be a number, got {value!r}") from None
    if not (np.isfinite(v) and v > 0):
        raise SampleError(f"{name} must be finite and > 0, got {value!r}")
    return v


def _check_sample_kw(sample_kw) -> None:
    clash = sorted(set(sample_kw) & {"positions", "radii", "bonds", "domain"})
    if clash:
        raise SampleError(f"{clash} are set by the generator and cannot be passed")


def _build(positions, radii, bonds, domain: Domain, bond_radius_ratio, sample_kw) -> Sample:
    kw = dict(sample_kw)
    if "bond_radius" not in kw:
        kw["bond_radius_ratio"] = bond_radius_ratio
    try:
        return Sample.from_arrays(positions, radii, bonds, domain=domain, **kw)
    except TypeError as err:  # an unknown keyword
        raise SampleError(f"unknown sample option: {err}") from None
