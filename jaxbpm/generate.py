"""Sample generators: regular lattices, random dense packings, and bond-material assignment.

* :func:`lattice` builds simple-cubic (``"sc"``) or face-centred-cubic (``"fcc"``) packings of equal touching
  spheres, bonded between nearest neighbours (exact, integer arithmetic), and in two dimensions square
  (``"square"``) or hexagonal (``"hex"``) lattices of discs (:func:`jaxbpm.discs.lattice2d`).
* :func:`disc_packing` (and the shortcut :func:`rectangle`) fills a rectangle, a disc or a beam with polydisperse
  discs: a two-dimensional sample (:mod:`jaxbpm.discs`).
* :func:`random_packing` (and the shortcuts :func:`box`, :func:`cylinder`, :func:`beam`) fills a box, a cylinder
  or a beam with polydisperse spheres: random insertion, then force-biased overlap removal with FIRE on a jax-md
  neighbour list, then a bond between every pair closer than a small surface gap.
* :func:`from_shape` is the entry point of ``jaxbpm generate``.
* :func:`mix_materials` and :func:`materials_by_region` assign bond material components (e.g. bi-component
  agglomerates) to an existing sample.

Every generator returns a validated :class:`~jaxbpm.sample.Sample` (NumPy ``float64`` leaves, SI units) whatever
JAX's precision setting; the packing itself runs in the float type JAX gives (``float32`` unless x64 is on). No
global JAX setting is changed: the jax-md calls run under local ``jax.numpy_dtype_promotion("standard")`` and
``jax.numpy_rank_promotion("allow")`` contexts, since jax-md is not written for the strict modes.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from jaxbpm._spatial import morton_order
from jaxbpm.discs import contact_pairs, disc_packing, lattice2d, LATTICES_2D
from jaxbpm.errors import SampleError
from jaxbpm.packing import jamming_fraction, Walls, pack, pack_auto
from jaxbpm.sample import BondMaterials, Domain, Sample

__all__ = [
    "lattice",
    "random_packing",
    "disc_packing",
    "rectangle",
    "box",
    "morton_order",
    "cylinder",
    "beam",
    "from_shape",
    "bond_pairs",
    "mix_materials",
    "materials_by_region",
    "SHAPES",
]

SHAPES = ("box", "cylinder", "beam", "sc", "fcc")
"""Shapes understood by :func:`from_shape` (and ``jaxbpm generate --shape``)."""

_RANDOM_SHAPES = ("box", "cylinder", "beam")
_DEFAULT_ASPECT = {"box": (1.0, 1.0, 1.0), "cylinder": 2.0, "beam": (4.0, 1.0, 1.0)}
_GENERATED = ("positions", "radii", "bonds", "domain")  # set by the generators, not accepted in sample_kw

# ---------------------------------------------------------------------------------------------------- lattices
# Half of the 6 SC and of the 12 FCC nearest-neighbour offsets (positive first non-zero component): each bond once.
_SC_OFFSETS = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]])
_FCC_OFFSETS = np.array([[1, 1, 0], [1, -1, 0], [1, 0, 1], [1, 0, -1], [0, 1, 1], [0, 1, -1]])


def lattice(kind: str, cells: tuple[int, ...], radius: float = 1e-3, *, bond_radius_ratio: float = 0.5,
            **sample_kw) -> Sample:
    """A regular packing of equal touching spheres (or discs), bonded between nearest neighbours.

    Args:
      kind: ``"sc"``: particles at ``(i, j, k) * 2 radius`` for ``i < nx``, ``j < ny``, ``k < nz``
        (``nx * ny * nz`` particles, up to 6 bonds each). ``"fcc"``: sites ``(i, j, k) * a / 2`` with lattice
        constant ``a = 2 sqrt(2) radius``, ``0 <= i <= 2 nx`` (likewise j, k) and ``i + j + k`` even
        (``((2nx+1)(2ny+1)(2nz+1) + 1) / 2`` particles, up to 12 bonds each). ``"square"``, ``"hex"``: a
        two-dimensional lattice of discs, see :func:`jaxbpm.discs.lattice2d` (``cells = (nx, ny)``).
      cells: ``(nx, ny, nz)``, each >= 1 (SC: particles per direction; FCC: unit cells per direction).
      radius: particle radius [m].
      bond_radius_ratio: bond radius / particle radius.
      **sample_kw: forwarded to :meth:`Sample.from_arrays` (``materials``, ``density``, ``particle_material``,
        ``bond_contact``, ``bond_material``, ...).

    Returns:
      A :class:`Sample` whose ``domain`` is the box enclosing the spheres; every bond has length ``2 radius``.
    """
    _check_sample_kw(sample_kw)
    kind = str(kind).lower()
    if kind in LATTICES_2D:
        return lattice2d(kind, cells, radius, bond_radius_ratio=bond_radius_ratio, **sample_kw)
    if kind not in ("sc", "fcc"):
        raise SampleError(f"lattice: kind must be 'sc' or 'fcc' (spheres), 'square' or 'hex' (discs), got {kind!r}")
    cells = _check_cells(cells)
    radius = _positive("radius", radius)
    if kind == "sc":
        ijk = _grid(cells)
        offsets, spacing = _SC_OFFSETS, 2.0 * radius
    else:
        ijk = _grid(tuple(2 * c + 1 for c in cells))
        ijk = ijk[ijk.sum(axis=1) % 2 == 0]
        offsets, spacing = _FCC_OFFSETS, np.sqrt(2.0) * radius  # a / 2
    bonds = _lattice_bonds(ijk, offsets)
    positions = ijk.astype(np.float64) * spacing
    hi = ijk.max(axis=0) * spacing + radius
    domain = Domain("box", (-radius,) * 3, tuple(float(v) for v in hi))
    return _build(positions, np.full(len(ijk), radius), bonds, domain, bond_radius_ratio, sample_kw)


def _grid(dims) -> np.ndarray:
    """All integer points ``[prod(dims), 3]`` of a ``dims`` grid, last index fastest."""
    return np.stack(np.meshgrid(*(np.arange(d) for d in dims), indexing="ij"), axis=-1).reshape(-1, 3)


def _lattice_bonds(ijk: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Bonds ``[nb, 2]`` between sites ``ijk [n, 3]`` (integer coordinates) that differ by one of ``offsets``."""
    dims = ijk.max(axis=0) + 1
    lookup = np.full(tuple(dims), -1, dtype=np.int64)
    lookup[tuple(ijk.T)] = np.arange(len(ijk))
    pairs = []
    for off in offsets:
        nb = ijk + off
        inside = np.all((nb >= 0) & (nb < dims), axis=1)
        j = np.full(len(ijk), -1, dtype=np.int64)
        j[inside] = lookup[tuple(nb[inside].T)]
        keep = j >= 0
        pairs.append(np.stack([np.flatnonzero(keep), j[keep]], axis=1))
    return _sorted_pairs(np.concatenate(pairs))


def _sorted_pairs(pairs: np.ndarray) -> np.ndarray:
    """Pairs ``[nb, 2]`` as int32 with i < j, sorted lexicographically."""
    pairs = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    return pairs.astype(np.int32)


def _check_cells(cells) -> tuple[int, int, int]:
    try:
        out = tuple(int(c) for c in cells)
        ok = len(out) == 3 and all(c == float(v) for c, v in zip(out, cells))
    except (TypeError, ValueError):
        ok = False
    if not ok or min(out) < 1:
        raise SampleError(f"lattice: cells must be three integers >= 1, got {cells!r}")
    return out


# ------------------------------------------------------------------------------------------------ random packing
AUTO_PACKING_FRACTIONS = (0.60, 0.58, 0.56, 0.55)
"""Packing fractions tried by :func:`random_packing` when none is given, densest first (smaller samples try
fewer of the dense ones and continue below 0.55, see there)."""
_AUTO_STEP, _AUTO_LOWEST = 0.02, 0.35


def random_packing(
    n: int,
    shape: str = "box",
    *,
    mean_radius: float = 1e-3,
    radius_spread: float = 0.05,
    aspect=None,
    packing_fraction: float | None = None,
    overlap_tol: float = 1e-3,
    bond_gap: float = 0.05,
    bond_radius_ratio: float = 0.5,
    seed: int = 0,
    max_steps: int = 200_000,
    progress: bool | Callable[[int, float, float], Any] = False,
    **sample_kw,
) -> Sample:
    """A dense random packing of polydisperse spheres filling a box, cylinder or beam, bonded at contacts.

    Radii are ``mean_radius * (1 + radius_spread * u)`` with ``u`` uniform in ``[-1, 1]`` (``radius_spread`` is
    the relative half-width of the distribution), clipped to stay positive. The domain volume is the total sphere
    volume over ``packing_fraction``; its lower corner is the origin:

    * ``"box"``: ``aspect = (ax, ay, az)`` (default ``(1, 1, 1)``) gives the edge ratios.
    * ``"beam"``: a box with default ``aspect = (4, 1, 1)``.
    * ``"cylinder"``: axis along z through ``(R, R)``, ``0 <= z <= H``; ``aspect = H / (2 R)`` (default 2).

    Centres are inserted at random inside the domain (stratified: one per randomly drawn cell of a grid of about
    one sphere's size, in the domain shrunk by the largest radius), then the overlaps are
    removed by minimising ``sum 0.5 * overlap^2`` over particle pairs plus the same harmonic penalty for spheres
    poking out of the walls, with FIRE on a jax-md neighbour list, in jitted chunks, until the largest overlap
    (pairs and walls) is below ``overlap_tol * mean_radius``. Finally every pair with surface gap
    ``distance - r_i - r_j < bond_gap * mean_radius`` is bonded.

    **Automatic packing fraction** (``packing_fraction=None``): fractions are tried densest first, each from the
    insertion an explicit ``packing_fraction`` of that value starts from, and the first that packs is kept. Walls
    pack loosely, so the fraction at which the spheres jam grows with the sample. An empirical estimate of it,
    ``0.645 - 0.2 S / V`` (``S / V``: wall area over domain volume, lengths in mean radii; fitted to boxes of 400
    to 4000 spheres with 5 % radius spread, and right for a 2000-sphere beam and cylinder too), chooses them: the
    values of ``AUTO_PACKING_FRACTIONS`` (0.60, 0.58, 0.56, 0.55) not above the estimate for their domain, and,
    for samples of fewer than about 300 spheres (whose walls loosen them most), fractions below 0.55 in steps of
    0.02, to one step below the estimate (a box of 60 spheres packs at 0.47 to 0.49, of 30 at 0.43 to 0.47).
    A fraction is tried

    * above the estimate (small samples only), in a short trial: it is given up when its largest overlap,
      extrapolated geometrically from its decay over the second half of the attempt (from step 400 on), would not
      reach the tolerance within 1500 FIRE steps, and after 1500 steps at the latest;
    * at or below it, until it packs or stalls: its largest overlap, at its lowest so far, fell by less than 10 %
      over the last 3000 steps (close to the jamming fraction, packing can take 10 000 steps);
    * the last one under the rule of an explicit ``packing_fraction`` (see Raises).

    Every attempt starts at rest and runs the same FIRE steps whatever was tried before it, and the samples are
    alike: the overlaps are removed from a random insertion at the fraction kept, so most bonded neighbours touch.
    All attempts share one compiled program, which is why the result, deterministic for a seed, is not bit for bit
    the sample of an explicit ``packing_fraction``.

    Args:
      n: number of particles.
      shape: ``"box"``, ``"cylinder"`` or ``"beam"``.
      mean_radius: mean particle radius [m].
      radius_spread: relative half-width of the uniform radius distribution [-], ``>= 0``.
      aspect: shape ratios, see above.
      packing_fraction: solid fraction of the domain [-]. Too high and the spheres jam: the overlaps cannot be
        removed. Walls pack loosely, so small samples jam earlier: with 5 % spread a box of 400 spheres packs 0.56
        but jams at 0.58, of 1000 packs 0.58 (slowly), of 2000 to 2500 jams at 0.6, of 3000 packs 0.6 (slowly).
        ``None`` (default): the densest fraction that packs, see above.
      overlap_tol: largest accepted overlap relative to ``mean_radius`` [-].
      bond_gap: bonding distance (surface gap) relative to ``mean_radius`` [-].
      bond_radius_ratio: bond radius / radius of the smaller particle of the pair.
      seed: seed of the NumPy generator used for the radii and the insertion (the result is deterministic).
      max_steps: FIRE step budget (per fraction tried).
      progress: ``True`` shows on stderr, per fraction tried, a bar of FIRE steps with the largest overlap / mean
        radius (:mod:`jaxbpm.progress`) and one line when it packed or was given up; a callable is called after
        every chunk of FIRE steps as ``progress(step, max_overlap_rel, elapsed_s)`` (step and time counted per
        fraction tried); ``False``/``None``: off.
      **sample_kw: forwarded to :meth:`Sample.from_arrays` (``materials``, ``density``, ``particle_material``,
        ``bond_contact``, ...).

    Returns:
      A :class:`Sample` with ``domain`` set (so ``packing_fraction()`` refers to the domain volume).

    Raises:
      SampleError: bad arguments, or the packing did not converge: ``max_steps`` ran out, or the spheres jammed
        (the largest overlap fell by less than 0.1 % over 5000 steps), which happens when ``packing_fraction``
        (with ``None``: the last of ``AUTO_PACKING_FRACTIONS``) is too high for the domain.
    """
    _check_sample_kw(sample_kw)
    n = _count("n", n, minimum=1)
    shape = str(shape).lower()
    if shape not in _RANDOM_SHAPES:
        raise SampleError(f"random_packing: shape must be one of {_RANDOM_SHAPES}, got {shape!r}")
    mean_radius = _positive("mean_radius", mean_radius)
    spread = _nonnegative("radius_spread", radius_spread)
    if spread >= 1:
        raise SampleError(f"radius_spread must be < 1 (radii are mean_radius * (1 + radius_spread * u), u in [-1, 1]: "
                          f"{spread:g} makes some of them zero or negative)")
    seed = _count("seed", seed, minimum=0)
    rng = np.random.default_rng(seed)
    radii = np.clip(1.0 + spread * rng.uniform(-1.0, 1.0, n), 1e-3, None)  # in units of mean_radius
    solid = float(np.sum(4.0 / 3.0 * np.pi * radii**3))
    if packing_fraction is None:
        fractions = _auto_fractions(shape, aspect, solid, float(radii.max()))
    else:
        fractions = (_positive("packing_fraction", packing_fraction),)
        if fractions[0] >= 0.74:
            raise SampleError(f"packing_fraction must be < 0.74 (random packings jam near 0.64), got {fractions[0]}")
    tol = _positive("overlap_tol", overlap_tol)
    gap = _nonnegative("bond_gap", bond_gap)
    max_steps = _count("max_steps", max_steps, minimum=1)
    seed = _count("seed", seed, minimum=0)
    if not (progress is None or isinstance(progress, bool) or callable(progress)):
        raise SampleError(f"progress must be a bool or a callable (step, max_overlap_rel, elapsed), got {progress!r}")

    walls = [_walls(shape, aspect, solid / phi, radii.max()) for phi in fractions]
    cutoff = 2.0 * (1.0 + spread)
    if packing_fraction is not None:
        x0, k = _insert(rng, walls[0], radii), 0
        x = pack(x0, radii, walls[0], cutoff, tol, max_steps, progress, fractions[0])
    else:
        def start(domain: Walls) -> np.ndarray:  # the insertion that an explicit packing_fraction starts from
            again = np.random.default_rng(seed)
            again.uniform(-1.0, 1.0, n)  # the radii
            return _insert(again, domain, radii)

        x, k = pack_auto(start, radii, walls, fractions, cutoff, tol, max_steps, progress)

    # particles numbered along a space-filling curve: neighbours in space are neighbours in memory
    order = morton_order(x)
    positions, radii = x[order] * mean_radius, radii[order] * mean_radius
    bonds = bond_pairs(positions, radii, gap * mean_radius)
    lo, hi = np.zeros(3), np.asarray(walls[k].size) * mean_radius
    domain = Domain("cylinder" if walls[k].cylinder else "box", tuple(lo.tolist()), tuple(hi.tolist()))
    return _build(positions, radii, bonds, domain, bond_radius_ratio, sample_kw)


def box(n: int, **kw) -> Sample:
    """A random packing filling a box.

    Args:
      n: number of particles.
      **kw: the keywords of :func:`random_packing` (``aspect`` default ``(1, 1, 1)``).

    Returns:
      The sample, see :func:`random_packing`.
    """
    return random_packing(n, shape="box", **kw)


def rectangle(n: int, **kw) -> Sample:
    """A random packing of discs filling a rectangle: a two-dimensional sample.

    Args:
      n: number of discs.
      **kw: the keywords of :func:`jaxbpm.discs.disc_packing` (``aspect`` default ``(1, 1)``, ``thickness``, ...).

    Returns:
      The sample, see :func:`jaxbpm.discs.disc_packing`.
    """
    return disc_packing(n, shape="rectangle", **kw)


def cylinder(n: int, **kw) -> Sample:
    """A random packing filling a z-axis cylinder.

    Args:
      n: number of particles.
      **kw: the keywords of :func:`random_packing` (``aspect`` = height / diameter, default 2).

    Returns:
      The sample, see :func:`random_packing`.
    """
    return random_packing(n, shape="cylinder", **kw)


def beam(n: int, **kw) -> Sample:
    """A random packing filling a beam (a box).

    Args:
      n: number of particles.
      **kw: the keywords of :func:`random_packing` (``aspect`` default ``(4, 1, 1)``).

    Returns:
      The sample, see :func:`random_packing`.
    """
    return random_packing(n, shape="beam", **kw)


def _auto_fractions(shape: str, aspect, solid: float, r_max: float) -> tuple[float, ...]:
    """The fractions the automatic mode tries, densest first: those of ``AUTO_PACKING_FRACTIONS`` not above the
    expected jamming fraction of their domain, then, while the expected jamming fraction of the loosest is below it
    (samples of fewer than about 300 spheres, whose walls loosen the packing more), fractions ``_AUTO_STEP`` apart
    downward, one past the first at or below its expected jamming fraction."""
    def expected(phi: float) -> float:
        return jamming_fraction(_walls(shape, aspect, solid / phi, r_max))

    fractions = [float(phi) for phi in AUTO_PACKING_FRACTIONS if phi <= expected(phi)]
    phi = float(AUTO_PACKING_FRACTIONS[-1])
    if expected(phi) < phi:
        while phi > _AUTO_LOWEST:
            phi = round(phi - _AUTO_STEP, 2)
            fractions.append(phi)
            if expected(phi) >= phi:
                fractions.append(round(phi - _AUTO_STEP, 2))
                break
    return tuple(fractions)


def _walls(shape: str, aspect, volume: float, r_max: float) -> Walls:
    """Domain of ``volume`` (in mean-radius units) with the ratios ``aspect``."""
    aspect = _DEFAULT_ASPECT[shape] if aspect is None else aspect
    if shape == "cylinder":
        h = _positive("aspect (cylinder height / diameter)", aspect)
        radius = (volume / (2.0 * np.pi * h)) ** (1.0 / 3.0)
        size = (2.0 * radius, 2.0 * radius, 2.0 * radius * h)
    else:
        a = np.asarray(aspect, dtype=np.float64) if np.ndim(aspect) == 1 else np.array([np.nan])
        if a.shape != (3,) or not np.all(np.isfinite(a) & (a > 0)):
            raise SampleError(f"aspect of a {shape} must be three positive edge ratios, got {aspect!r}")
        size = tuple((a * (volume / np.prod(a)) ** (1.0 / 3.0)).tolist())
    if min(size) <= 2.0 * r_max:
        raise SampleError(f"the {shape} domain ({min(size) / 2:.3g} mean radii across) is too thin for the "
                          f"largest sphere; use more particles or a less elongated aspect")
    return Walls(shape == "cylinder", tuple(float(s) for s in size))


def _insert(rng: np.random.Generator, walls: Walls, radii: np.ndarray) -> np.ndarray:
    """Random centres ``[n, 3]`` inside the domain shrunk by the largest radius, stratified: the shrunk domain is
    cut into at least ``n`` near-cubic grid cells, ``n`` of them are drawn at random and each receives one centre
    uniformly inside it. This keeps the start free of crowded spots (Poisson clumps), which makes the first FIRE
    steps calmer and the neighbour list smaller, without any order: the cells are about one sphere across."""
    n, size = len(radii), np.asarray(walls.size)
    r_max = float(radii.max())
    inner = size - 2.0 * r_max  # > 0: checked by _walls
    big = size[0] / 2.0
    h = (float(np.prod(inner)) * (np.pi / 4.0 if walls.cylinder else 1.0) / n) ** (1.0 / 3.0)
    while True:
        m = np.maximum(np.floor(inner / h).astype(np.int64), 1)
        centres = (_grid(m) + 0.5) / m * inner + r_max
        if walls.cylinder:
            cells = np.flatnonzero(np.hypot(centres[:, 0] - big, centres[:, 1] - big) <= big - r_max)
        else:
            cells = np.arange(len(centres))
        if len(cells) >= n:
            break
        h *= 0.95
    x = centres[rng.choice(cells, n, replace=False)] + rng.uniform(-0.5, 0.5, (n, 3)) * (inner / m)
    if walls.cylinder:  # cells cut by the side wall: pull their centres radially inside
        d = x[:, :2] - big
        rho = np.hypot(d[:, 0], d[:, 1])
        x[:, :2] = big + d * (np.minimum(rho, big - radii) / np.maximum(rho, 1e-300))[:, None]
    return x


# ----------------------------------------------------------------------------------------------------- from_shape
def from_shape(shape: str, n: int, *, seed: int = 0, progress=False, **kw) -> Sample:
    """A sample of about ``n`` particles of a named shape (the ``jaxbpm generate`` command).

    Args:
      shape: ``"box"``, ``"cylinder"``, ``"beam"`` (random packings, :func:`random_packing`) or ``"sc"``,
        ``"fcc"`` (a cube lattice, :func:`lattice`, whose cell count gives the particle count closest to ``n``,
        at least 2 cells per direction).
      n: number of particles (exact for random packings, approximate for lattices).
      seed: random seed (random packings only).
      progress: progress reporting, see :func:`random_packing` (random packings only).
      **kw: forwarded to :func:`random_packing` or :func:`lattice` (e.g. ``packing_fraction``, ``materials``,
        ``density``); for lattices ``mean_radius`` is accepted as the ``radius``.

    Returns:
      The sample.

    Raises:
      SampleError: an unknown shape or bad arguments.
    """
    key = str(shape).lower()
    if key not in SHAPES:
        raise SampleError(f"unknown shape {shape!r}; valid shapes are {', '.join(SHAPES)}")
    n = _count("n", n, minimum=1)
    if key in _RANDOM_SHAPES:
        return random_packing(n, shape=key, seed=seed, progress=progress, **kw)
    if "mean_radius" in kw:
        if "radius" in kw:
            raise SampleError("give radius or mean_radius, not both")
        kw["radius"] = kw.pop("mean_radius")
    count = (lambda c: c**3) if key == "sc" else (lambda c: ((2 * c + 1) ** 3 + 1) // 2)
    c = 2
    while count(c + 1) <= n:
        c += 1
    if abs(count(c + 1) - n) < abs(count(c) - n):
        c += 1
    return lattice(key, (c, c, c), **kw)


# ----------------------------------------------------------------------------------------------------------- bonds
def bond_pairs(positions, radii, gap: float) -> np.ndarray:
    """Pairs of spheres (or discs) whose surface gap ``|x_j - x_i| - r_i - r_j`` is below ``gap``.

    Args:
      positions: ``[n, 3]`` centres [m] (``[n, 2]``: discs).
      radii: ``[n]`` radii [m].
      gap: largest surface gap of a bonded pair [m] (overlapping pairs, negative gaps, are included).

    Returns:
      ``[nb, 2]`` int32 particle indices, ``i < j``, sorted lexicographically.
    """
    return contact_pairs(positions, radii, gap)


# ------------------------------------------------------------------------------------------------------- materials
def mix_materials(sample: Sample, fractions, *, seed: int = 0, materials=None) -> Sample:
    """Assign bond material components at random by mixing ratio (e.g. bi-component agglomerates).

    Args:
      sample: the sample whose bonds get new components.
      fractions: ``[k]`` mixing ratio per component, each >= 0, summing to 1 (within 1e-9). Component ``c``
        gets exactly ``round(fractions[c] * nb)`` bonds (halves rounded up; never more than are left) for
        ``c < k - 1`` and the last component the remainder.
      seed: seed of the NumPy generator that permutes the assignment.
      materials: optional new material table (mapping ``{"E": [...], "nu": [...], ...}`` or
        :class:`BondMaterials`) with ``k`` components; by default the sample's table, which must have ``k``.

    Returns:
      ``sample.replace(bond_material=..., materials=...)``.
    """
    frac = np.asarray(fractions, dtype=np.float64) if _is_numeric(fractions) else np.array([np.nan])
    if frac.ndim != 1 or frac.size == 0 or not np.all(np.isfinite(frac)):
        raise SampleError(f"mix_materials: fractions must be a non-empty 1-D list of numbers, got {fractions!r}")
    if np.any(frac < 0):
        raise SampleError(f"mix_materials: fractions must be >= 0, got {frac.tolist()}")
    if abs(float(frac.sum()) - 1.0) > 1e-9:
        raise SampleError(f"mix_materials: fractions must sum to 1, got {frac.tolist()} (sum {frac.sum():.12g})")
    table = _table(sample, materials, len(frac), "mix_materials")
    nb = sample.n_bonds
    counts = np.zeros(len(frac), dtype=np.int64)
    left = nb
    for c, f in enumerate(frac[:-1]):
        counts[c] = min(int(np.floor(f * nb + 0.5)), left)
        left -= counts[c]
    counts[-1] = left
    seed = _count("seed", seed, minimum=0)
    labels = np.repeat(np.arange(len(frac), dtype=np.int32), counts)
    return sample.replace(bond_material=np.random.default_rng(seed).permutation(labels), materials=table)


def materials_by_region(sample: Sample, region: Callable[[np.ndarray], Any], *, materials=None) -> Sample:
    """Assign each bond the material component ``region`` gives its midpoint.

    Args:
      sample: the sample whose bonds get new components.
      region: called with the bond midpoints ``[nb, 3]`` (NumPy, m); returns ``[nb]`` integer (or boolean)
        component indices.
      materials: optional new material table (mapping or :class:`BondMaterials`); default the sample's.

    Returns:
      ``sample.replace(bond_material=..., materials=...)``.
    """
    if not callable(region):
        raise SampleError(f"materials_by_region: region must be a callable of the bond midpoints, got {region!r}")
    table = _table(sample, materials, None, "materials_by_region")
    b, pos = np.asarray(sample.bonds), np.asarray(sample.positions)
    labels = np.asarray(region(0.5 * (pos[b[:, 0]] + pos[b[:, 1]])))
    if labels.dtype == np.bool_:
        labels = labels.astype(np.int32)
    if labels.shape != (sample.n_bonds,) or not np.issubdtype(labels.dtype, np.integer):
        raise SampleError(f"materials_by_region: region must return [{sample.n_bonds}] integer component indices, "
                          f"got shape {labels.shape} dtype {labels.dtype}")
    return sample.replace(bond_material=labels.astype(np.int32), materials=table)


def _table(sample: Sample, materials, k: int | None, who: str) -> BondMaterials:
    """The material table to use (new or the sample's), checked to have ``k`` components when given."""
    if materials is None:
        table = sample.materials
        if k is not None and table.n != k:
            raise SampleError(f"{who}: the sample's material table has {table.n} components but {k} fractions "
                              f"were given; pass materials= with {k} components")
        return table
    if isinstance(materials, BondMaterials):
        table = BondMaterials.create(materials.E, materials.nu, materials.tensile_strength, materials.shear_strength)
    elif isinstance(materials, Mapping):
        unknown = set(materials) - {"E", "nu", "tensile_strength", "shear_strength"}
        if unknown:
            raise SampleError(f"{who}: materials has unknown fields {sorted(unknown)}")
        if "E" not in materials:
            raise SampleError(f"{who}: materials is missing 'E' (bond Young's modulus per component)")
        table = BondMaterials.create(**materials)
    else:
        raise SampleError(f"{who}: materials must be a mapping or a BondMaterials, got {type(materials).__name__}")
    if k is not None and table.n != k:
        raise SampleError(f"{who}: materials has {table.n} components but {k} fractions were given")
    return table


# --------------------------------------------------------------------------------------------------------- helpers
def _check_sample_kw(sample_kw) -> None:
    clash = sorted(set(sample_kw) & set(_GENERATED))
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


def _is_numeric(x) -> bool:
    try:
        arr = np.asarray(x)
    except (TypeError, ValueError):
        return False
    return np.issubdtype(arr.dtype, np.number) and not np.issubdtype(arr.dtype, np.complexfloating)


def _positive(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SampleError(f"{name} must be a number, got {value!r}") from None
    if not (np.isfinite(v) and v > 0):
        raise SampleError(f"{name} must be finite and > 0, got {value!r}")
    return v


def _nonnegative(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SampleError(f"{name} must be a number, got {value!r}") from None
    if not (np.isfinite(v) and v >= 0):
        raise SampleError(f"{name} must be finite and >= 0, got {value!r}")
    return v


def _count(name: str, value, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise SampleError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)
