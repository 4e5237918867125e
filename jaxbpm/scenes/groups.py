"""Boundary groups: the particles a scene clamps or moves, written as one writes them for LAMMPS, PFC or Yade.

A scene's group field (``UniaxialCompression(fixed=..., driven=...)``, ``ThreePointBending(supports=..., punch=...)``,
``BrazilianDisc(fixed=..., driven=...)``) takes any of:

* a boolean mask ``[n]``;
* a list (or integer array) of particle indices, 0-based, as :class:`Ids`;
* :class:`Type` ``(k, ...)``: the particles whose :attr:`Sample.types <jaxbpm.sample.Sample>` is one of ``k``
  (LAMMPS ``group top type 2``; a Yade or MUSEN material or group column read into ``types``);
* :class:`Region` ``.box(lo, hi)``, ``.slab(axis, lo, hi)``, ``.cylinder(axis, centre, radius, lo, hi)``,
  ``.sphere(centre, radius)``: the particles whose centres lie inside, bounds included (LAMMPS ``region`` +
  ``group name region``; ``None`` for an open side, as LAMMPS's ``INF``);
* :class:`Layer` ``(thickness, end="low" | "high")``: the particles whose centres lie within ``thickness`` of the
  lowest (highest) centre along the scene's axis (the scenes' default layers);
* ``a | b``, ``a & b``, ``a - b``, ``~a`` of the above (LAMMPS ``group union``, ``intersect``, ``subtract``; a
  region's ``side out``).

A scene keeps a group as it is given; :func:`clamped_groups` turns the pair into masks when the scene's ``layers`` is
called (once per sample and scene: the masks are cached), and raises :class:`~jaxbpm.errors.GroupError` naming the
group and the particles for a group that selects nothing or does not fit the sample, two groups that share particles,
and particles of one group with no bond path to the other (they carry no load; the message says which; where the scene
has contacts, a group's particle touching another at rest is joined to it, as a roller disc resting on a beam).
The specs are frozen and hashable, so a scene holding them keys the solvers' setup caches as it is.
"""

from __future__ import annotations

import collections
import dataclasses
import weakref

import numpy as np

from jaxbpm._compile import content_key, hashable
from jaxbpm._validate import listed
from jaxbpm.errors import GroupError
from jaxbpm.sample import Sample

__all__ = ["Group", "Ids", "Type", "Region", "Layer", "select", "clamped_groups", "touching_pairs"]

_AXES = "xyz"


class Group:
    """A rule that picks particles of a sample; combine with ``|``, ``&``, ``-`` and ``~``."""

    def mask(self, sample: Sample, axis: int = 2, layer_thickness: float | None = None) -> np.ndarray:
        """The particles the rule picks.

        Args:
          sample: the specimen.
          axis: the scene's load axis (what :class:`Layer` measures along).
          layer_thickness: the scene's layer thickness [m] (:class:`Layer` without its own; ``None``: one mean
            particle radius).

        Returns:
          ``[n]`` booleans (possibly none True).
        """
        raise NotImplementedError

    def __or__(self, other):
        return _Combined("|", self, _spec(other))

    def __and__(self, other):
        return _Combined("&", self, _spec(other))

    def __sub__(self, other):
        return _Combined("-", self, _spec(other))

    def __invert__(self):
        return _Combined("~", self, None)


@dataclasses.dataclass(frozen=True, repr=False)
class _Combined(Group):
    """Two groups combined (``|``, ``&``, ``-``) or one inverted (``~``)."""

    op: str
    left: Group
    right: Group | None

    def mask(self, sample, axis=2, layer_thickness=None):
        a = self.left.mask(sample, axis, layer_thickness)
        if self.op == "~":
            return ~a
        b = self.right.mask(sample, axis, layer_thickness)
        return {"|": a | b, "&": a & b, "-": a & ~b}[self.op]

    def __repr__(self):
        return f"~({self.left!r})" if self.op == "~" else f"({self.left!r} {self.op} {self.right!r})"


@dataclasses.dataclass(frozen=True, init=False, repr=False)
class Ids(Group):
    """Particles by index (0-based, the sample's order; LAMMPS ``group name id``, whose ids count from 1: subtract 1).

    Args:
      indices: whole numbers, each in ``0 .. n - 1`` (checked against the sample when the group is resolved).

    Raises:
      GroupError: indices that are not whole numbers.
    """

    indices: tuple[int, ...]

    def __init__(self, indices):
        arr = np.asarray(indices if not isinstance(indices, range) else list(indices))
        if arr.size == 0:
            arr = arr.astype(np.int64)
        if arr.ndim > 1 or arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer):
            raise GroupError(f"Ids takes a list of whole particle indices, got {_shown(indices)}")
        object.__setattr__(self, "indices", tuple(int(i) for i in np.atleast_1d(arr)))

    def mask(self, sample, axis=2, layer_thickness=None):
        m = np.zeros(sample.n_particles, bool)
        m[np.asarray(self.indices, np.int64)] = True
        return m

    def __repr__(self):
        return f"Ids({listed(self.indices)})"


@dataclasses.dataclass(frozen=True, init=False, repr=False)
class Type(Group):
    """Particles by type: those whose ``Sample.types`` is one of ``types`` (LAMMPS ``group name type 1 2``).

    Args:
      *types: whole numbers.

    Raises:
      GroupError: no type, or one that is not a whole number.
    """

    types: tuple[int, ...]

    def __init__(self, *types):
        flat = [t for item in types for t in (item if isinstance(item, (list, tuple, range)) else [item])]
        if not flat or not all(isinstance(t, (int, np.integer)) and not isinstance(t, bool) for t in flat):
            raise GroupError(f"Type takes one or more whole numbers, got {_shown(types)}")
        object.__setattr__(self, "types", tuple(sorted({int(t) for t in flat})))

    def mask(self, sample, axis=2, layer_thickness=None):
        return np.isin(_types(sample), self.types)

    def __repr__(self):
        return f"Type({', '.join(map(str, self.types))})"


def _bound(v, default: float) -> float:
    return default if v is None else float(v)


@dataclasses.dataclass(frozen=True, repr=False)
class Region(Group):
    """Particles whose centres lie in a region (bounds included); build one with :meth:`box`, :meth:`slab`,
    :meth:`cylinder` or :meth:`sphere`.

    Attributes:
      kind: ``"box"``, ``"cylinder"`` or ``"sphere"`` (a slab is a box open along two axes).
      lo, hi: the box's corners [m] (``-inf`` / ``inf`` where open); a cylinder's extent along its axis.
      axis: a cylinder's axis (0, 1, 2).
      centre: a cylinder's centre across its axis (2 values, the other axes in order: for z, x and y) or a
        sphere's centre (3 values) [m].
      radius: a cylinder's or sphere's radius [m].
    """

    kind: str
    lo: tuple[float, ...] = ()
    hi: tuple[float, ...] = ()
    axis: int = 2
    centre: tuple[float, ...] = ()
    radius: float = 0.0

    @classmethod
    def box(cls, lo, hi) -> "Region":
        """An axis-aligned box (LAMMPS ``region name block xlo xhi ylo yhi zlo zhi``).

        Args:
          lo, hi: 3 bounds each [m]; ``None`` (or an infinite value) for an open side.

        Returns:
          The region.

        Raises:
          GroupError: bounds that are not 3 numbers, or ``lo > hi``.
        """
        if len(lo) != 3 or len(hi) != 3:
            raise GroupError(f"Region.box takes 3 lower and 3 upper bounds, got {_shown(lo)}, {_shown(hi)}")
        lo_t = tuple(_bound(v, -np.inf) for v in lo)
        hi_t = tuple(_bound(v, np.inf) for v in hi)
        if any(a > b or np.isnan(a) or np.isnan(b) for a, b in zip(lo_t, hi_t)):
            raise GroupError(f"Region.box needs lo <= hi on every axis, got lo {list(lo_t)}, hi {list(hi_t)}")
        return cls("box", lo_t, hi_t)

    @classmethod
    def slab(cls, axis: int, lo=None, hi=None) -> "Region":
        """A slab normal to ``axis``: ``lo <= x_axis <= hi``, open along the other two axes.

        Args:
          axis: 0, 1 or 2.
          lo, hi: the bounds [m] along ``axis`` (``None``: open).

        Returns:
          The region.

        Raises:
          GroupError: a bad axis or ``lo > hi``.
        """
        _check_axis(axis, "Region.slab")
        lo3, hi3 = [None] * 3, [None] * 3
        lo3[axis], hi3[axis] = lo, hi
        return cls.box(lo3, hi3)

    @classmethod
    def cylinder(cls, axis: int, centre, radius: float, lo=None, hi=None) -> "Region":
        """A cylinder along ``axis`` (LAMMPS ``region name cylinder z c1 c2 radius lo hi``).

        Args:
          axis: 0, 1 or 2.
          centre: the axis's position across it: 2 values, the other two coordinates in order [m].
          radius: [m], > 0.
          lo, hi: the extent along ``axis`` [m] (``None``: open).

        Returns:
          The region.

        Raises:
          GroupError: a bad axis, centre or radius, or ``lo > hi``.
        """
        _check_axis(axis, "Region.cylinder")
        if len(centre) != 2 or not float(radius) > 0:
            raise GroupError(f"Region.cylinder takes a centre of 2 coordinates across the axis and a radius > 0, got "
                             f"{_shown(centre)}, {_shown(radius)}")
        a, b = _bound(lo, -np.inf), _bound(hi, np.inf)
        if a > b:
            raise GroupError(f"Region.cylinder needs lo <= hi, got {a}, {b}")
        return cls("cylinder", (a,), (b,), int(axis), tuple(float(c) for c in centre), float(radius))

    @classmethod
    def sphere(cls, centre, radius: float) -> "Region":
        """A sphere (LAMMPS ``region name sphere x y z radius``).

        Args:
          centre: 3 coordinates [m].
          radius: [m], > 0.

        Returns:
          The region.

        Raises:
          GroupError: a bad centre or radius.
        """
        if len(centre) != 3 or not float(radius) > 0:
            raise GroupError(f"Region.sphere takes a centre of 3 coordinates and a radius > 0, got {_shown(centre)}, "
                             f"{_shown(radius)}")
        return cls("sphere", centre=tuple(float(c) for c in centre), radius=float(radius))

    def mask(self, sample, axis=2, layer_thickness=None):
        pos = np.asarray(sample.positions, np.float64)
        if self.kind == "box":
            return np.all((pos >= np.asarray(self.lo)) & (pos <= np.asarray(self.hi)), axis=1)
        if self.kind == "sphere":
            return np.sum((pos - np.asarray(self.centre)) ** 2, axis=1) <= self.radius ** 2
        across = [k for k in range(3) if k != self.axis]
        r2 = np.sum((pos[:, across] - np.asarray(self.centre)) ** 2, axis=1)
        x = pos[:, self.axis]
        return (r2 <= self.radius ** 2) & (x >= self.lo[0]) & (x <= self.hi[0])

    def __repr__(self):
        if self.kind == "sphere":
            return f"Region.sphere({list(self.centre)}, {self.radius:g})"
        if self.kind == "cylinder":
            return (f"Region.cylinder({_AXES[self.axis]!r}, {list(self.centre)}, {self.radius:g}, {self.lo[0]:g}, "
                    f"{self.hi[0]:g})")
        return f"Region.box({[float(v) for v in self.lo]}, {[float(v) for v in self.hi]})"


@dataclasses.dataclass(frozen=True)
class Layer(Group):
    """The particles whose centres lie within ``thickness`` of the lowest (``end="low"``) or highest (``"high"``)
    centre along an axis: the layers the scenes clamp by default.

    Args:
      thickness: [m] (``None``: the scene's ``layer_thickness``, else one mean particle radius).
      end: ``"low"`` or ``"high"``.
      axis: 0, 1 or 2 (``None``: the scene's load axis).

    Raises:
      GroupError: a bad end, axis or thickness.
    """

    thickness: float | None = None
    end: str = "low"
    axis: int | None = None

    def __post_init__(self):
        if self.end not in ("low", "high"):
            raise GroupError(f"Layer end must be 'low' or 'high', got {_shown(self.end)}")
        if self.axis is not None:
            _check_axis(self.axis, "Layer")
        if self.thickness is not None and not (isinstance(self.thickness, (int, float, np.integer, np.floating))
                                               and self.thickness >= 0 and np.isfinite(self.thickness)):
            raise GroupError(f"Layer thickness must be a length >= 0 [m], got {_shown(self.thickness)}")

    def mask(self, sample, axis=2, layer_thickness=None):
        z = np.asarray(sample.positions)[:, axis if self.axis is None else self.axis]
        t = next(v for v in (self.thickness, layer_thickness, float(np.mean(sample.radii))) if v is not None)
        return z <= z.min() + t if self.end == "low" else z >= z.max() - t


def _check_axis(axis, who: str) -> None:
    if not (isinstance(axis, (int, np.integer)) and not isinstance(axis, bool) and int(axis) in (0, 1, 2)):
        raise GroupError(f"{who}: axis must be 0, 1 or 2, got {_shown(axis)}")


def _shown(value) -> str:
    from jaxbpm._text import shown

    return shown(value)


def _types(sample: Sample) -> np.ndarray:
    return np.ones(sample.n_particles, np.int32) if sample.types is None else np.asarray(sample.types)


def _spec(value) -> Group | np.ndarray:
    """``value`` as a :class:`Group`, or as a boolean mask array (checked for its length on resolution)."""
    if isinstance(value, Group):
        return value
    if isinstance(value, (bool, int, float, str, np.integer, np.floating)) or value is None:
        raise GroupError(f"a group is a boolean mask, a list of particle indices, Ids(...), Type(k), Region.box/slab/"
                         f"cylinder/sphere(...) or Layer(...), got {_shown(value)} (one particle: Ids([k]); a type: "
                         f"Type(k))")
    arr = np.asarray(value)
    if arr.dtype == bool:
        return arr
    return Ids(value)


def select(group, sample: Sample, *, axis: int = 2, layer_thickness: float | None = None,
           name: str = "group") -> np.ndarray:
    """The particles of one group, checked.

    Args:
      group: a mask, indices or a :class:`Group` (see the module's text).
      sample: the specimen.
      axis: the scene's load axis.
      layer_thickness: the scene's layer thickness [m] (for a :class:`Layer` without its own).
      name: the group's name in messages (``"fixed"``, ...).

    Returns:
      ``[n]`` booleans, at least one True.

    Raises:
      GroupError: a mask of the wrong length, an index out of range, a type the sample does not have, or a group
        that selects nothing.
    """
    spec, n = _spec(group), sample.n_particles
    if isinstance(spec, np.ndarray):
        if spec.shape != (n,):
            raise GroupError(f"{name} mask must have shape [{n}] (one entry per particle), got {spec.shape}", name)
        mask, what = spec, "the mask"
    else:
        _check_fits(spec, sample, name)
        if isinstance(spec, Ids) and len(spec.indices) == n > 2 and set(spec.indices) <= {0, 1}:
            raise GroupError(f"{name}: {n} indices, each 0 or 1, look like a mask written in whole numbers: give a "
                             f"mask as booleans (np.asarray(m, bool)), particle indices as Ids([...])", name)
        mask, what = spec.mask(sample, axis, layer_thickness), repr(spec)
    if not mask.any():
        raise GroupError(f"{name}: {what} selects no particle{_where(spec, sample)}; a group must hold at least one "
                         f"particle", name)
    return mask


def _check_fits(spec: Group, sample: Sample, name: str) -> None:
    """Raise for indices outside the sample and types it does not have, here or inside a combination."""
    if isinstance(spec, _Combined):
        for part in (spec.left, spec.right):
            if part is not None:
                _check_fits(part, sample, name)
    elif isinstance(spec, Ids):
        idx = np.asarray(spec.indices, np.int64)
        bad = idx[(idx < 0) | (idx >= sample.n_particles)]
        if bad.size:
            raise GroupError(f"{name}: particle indices {listed(bad)} are out of range: the sample has "
                             f"{sample.n_particles} particles, 0..{sample.n_particles - 1}", name, bad)
    elif isinstance(spec, Type):
        present = np.unique(_types(sample))
        missing = sorted(set(spec.types) - set(present.tolist()))
        if missing:
            raise GroupError(f"{name}: {spec!r}: the sample has no particle of type {listed(missing)}; its types are "
                             f"{listed(present)}", name)


def _where(spec, sample: Sample) -> str:
    """Where the sample's centres lie, for the message of a region that selects nothing."""
    if not isinstance(spec, (Region, _Combined)):
        return ""
    pos = np.asarray(sample.positions)
    lo, hi = pos.min(axis=0).tolist(), pos.max(axis=0).tolist()
    return f" (the particle centres span {[float(f'{v:.6g}') for v in lo]} .. {[float(f'{v:.6g}') for v in hi]})"


def touching_pairs(sample: Sample, group: np.ndarray, tol: float | None = None) -> np.ndarray:
    """The pairs of particles, one of ``group``, that touch at rest: a path for the load where contacts are on.

    Args:
      sample: the specimen.
      group: ``[n]`` booleans, the particles whose contacts are looked for.
      tol: the largest gap [m] of a pair that touches (``None``: 1e-6 of the mean particle radius).

    Returns:
      ``[k, 2]`` integer pairs ``(i, j)``, ``i`` in ``group``, ``j != i``, whose gap ``|x_j - x_i| - r_i - r_j`` is
      at most ``tol``.
    """
    from scipy.spatial import cKDTree

    pos, rad = np.asarray(sample.positions, np.float64), np.asarray(sample.radii, np.float64)
    tol = 1e-6 * float(np.mean(rad)) if tol is None else float(tol)
    rows = np.flatnonzero(group)
    near = cKDTree(pos).query_ball_point(pos[rows], rad[rows] + rad.max() + tol)
    pairs = np.array([(i, j) for i, js in zip(rows, near) for j in js if j != i], np.int64).reshape(-1, 2)
    gap = np.linalg.norm(pos[pairs[:, 1]] - pos[pairs[:, 0]], axis=1) - rad[pairs[:, 0]] - rad[pairs[:, 1]]
    return pairs[gap <= tol]


def _connection(sample: Sample, group: np.ndarray, other: np.ndarray, names: tuple[str, str], touching=None) -> None:
    """Raise where particles of ``group`` lie in clusters (of bonds, and of the ``touching`` pairs) that hold no
    particle of ``other``."""
    labels = sample.clusters(touching)
    path = "bond path" if touching is None else "path of bonds or contacts"
    reaches = np.zeros(labels.max() + 1, bool)
    reaches[labels[other]] = True
    cut = np.flatnonzero(group & ~reaches[labels])
    if not cut.size:
        return
    if cut.size == group.sum():
        raise GroupError(f"no {path} joins {names[0]} and {names[1]}: the sample carries no load between them "
                         f"(their particles lie in different bonded clusters; Sample.clusters() labels them)",
                         names[0], cut)
    raise GroupError(f"{names[0]} particles {listed(cut)} have no {path} to {names[1]} (they lie in bonded "
                     f"clusters that hold no {names[1]} particle, so they carry no load): leave them out of the "
                     f"group, or solve sample.largest_cluster()", names[0], cut)


_RESOLVED: collections.OrderedDict = collections.OrderedDict()  # (id(sample), key) -> (weakref, fixed, driven)


def clamped_groups(sample: Sample, first, second, *, axis: int = 2, layer_thickness: float | None = None,
                   names: tuple[str, str] = ("fixed", "driven"),
                   contacts: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The masks of a scene's two clamped groups, checked against each other; cached per sample and groups.

    Args:
      sample: the specimen.
      first, second: the two groups (a mask, indices or a :class:`Group` each).
      axis: the scene's load axis.
      layer_thickness: the scene's layer thickness [m] (for a :class:`Layer` without its own).
      names: the groups' names in messages.
      contacts: the scene has contacts: a group's particle that touches another particle at rest
        (:func:`touching_pairs`) is joined to it as by a bond (a roller disc resting on a beam carries the load
        through its contact).

    Returns:
      ``(first [n], second [n])``: boolean masks, each non-empty, disjoint.

    Raises:
      GroupError: as :func:`select`; particles in both groups; particles of one group with no path to the other
        (of bonds; with ``contacts``, of bonds and of the groups' contacts at rest).
    """
    key = (first, second, axis, layer_thickness, names, bool(contacts))
    key = key if hashable(key) else content_key(key)
    hit = _RESOLVED.get((id(sample), key)) if key is not None else None
    if hit is not None and hit[0]() is sample:
        return hit[1].copy(), hit[2].copy()
    a = select(first, sample, axis=axis, layer_thickness=layer_thickness, name=names[0])
    b = select(second, sample, axis=axis, layer_thickness=layer_thickness, name=names[1])
    both = np.flatnonzero(a & b)
    if both.size:
        raise GroupError(f"{both.size} particles are in both {names[0]} and {names[1]}: {listed(both)}; give "
                         f"disjoint groups (for layers, a thinner layer_thickness)", names[0], both)
    touching = touching_pairs(sample, a | b) if contacts else None
    _connection(sample, b, a, names[::-1], touching)
    _connection(sample, a, b, names, touching)
    if key is not None:
        _RESOLVED[(id(sample), key)] = (weakref.ref(sample), a, b)
        while len(_RESOLVED) > 32:
            _RESOLVED.popitem(last=False)
    return a.copy(), b.copy()
