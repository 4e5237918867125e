"""The bonded sample: particles, bonds and their materials, as one validated JAX pytree.

A :class:`Sample` is built once from plain arrays with :meth:`Sample.from_arrays`, which checks every input and
computes the per-bond and per-particle quantities the solvers need (bond length, area, second moments of area;
particle mass and moment of inertia). All quantities are in SI units (m, kg, Pa, N).

The array leaves are NumPy ``float64``/``int32`` arrays, so a sample round-trips exactly through files whatever
JAX's precision setting; solvers convert them with ``jnp.asarray`` when they start.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping, NamedTuple

import jax
import numpy as np

from jaxbpm._geometry import bond_section, checked_thickness, particle_mass, solid_measure
from jaxbpm._spatial import morton_order
from jaxbpm._summary import SampleSummary
from jaxbpm._text import shown
from jaxbpm._validate import (bond_lengths, checked_bond_material, checked_bond_radius, checked_bonds,
                              checked_positions, checked_radii, checked_types, listed)
from jaxbpm.errors import SampleError

__all__ = ["Sample", "BondMaterials", "ParticleMaterial", "Domain", "SampleSummary"]



class Domain(NamedTuple):
    """The region a generated sample fills, used for its packing fraction.

    kind: ``"box"`` (also used for beams; a rectangle in 2D) or ``"cylinder"`` (axis along z; a disc in 2D).
    lo, hi: corners of the bounding box of the region [m], three coordinates each (two in 2D).
    """

    kind: str
    lo: tuple[float, ...]
    hi: tuple[float, ...]

    @property
    def volume(self) -> float:
        """The region's volume [m^3] (a cylinder: the one inscribed in the box, pi a b h / 4), in 2D its area [m^2]
        (a disc: the ellipse inscribed in the rectangle, pi a b / 4)."""
        size = np.subtract(self.hi, self.lo)
        if self.kind == "cylinder":
            return float(np.pi * size[0] * size[1] / 4.0 * np.prod(size[2:]))
        return float(np.prod(size))


def _register(cls, data, meta=()):
    return jax.tree_util.register_dataclass(cls, data_fields=list(data), meta_fields=list(meta))


def _numbers(name: str, value) -> np.ndarray:
    """``value`` as float64, or a :class:`SampleError` naming the material field (not a bare ``ValueError``)."""
    try:
        arr = np.asarray(value)
        if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == object) or \
                np.issubdtype(arr.dtype, np.complexfloating):
            raise TypeError
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise SampleError(f"materials: {name} must be numbers, got {shown(value)}") from None


@dataclasses.dataclass(frozen=True)
class BondMaterials:
    """Material table, one entry per bond component (index = ``Sample.bond_material``).

    E: Young's modulus of the bond material [Pa], shape ``[n_materials]``.
    nu: Poisson ratio [-].
    tensile_strength, shear_strength: bond strengths [Pa] (``inf`` = unbreakable).
    """

    E: Any
    nu: Any
    tensile_strength: Any
    shear_strength: Any

    @property
    def n(self) -> int:
        """The number of material components."""
        return int(np.shape(self.E)[0])

    @classmethod
    def create(cls, E, nu=0.25, tensile_strength=np.inf, shear_strength=np.inf) -> "BondMaterials":
        """Build and check a table; scalars broadcast to the number of components given by ``E``.

        Args:
          E: ``[k]`` (or a scalar) bond Young's moduli [Pa], finite and > 0.
          nu: Poisson ratios [-] in (-1, 0.5).
          tensile_strength: [Pa], > 0 (``inf``: unbreakable).
          shear_strength: [Pa], > 0 (``inf``: unbreakable).

        Returns:
          The table, each field ``[k]`` float64.

        Raises:
          SampleError: a field is not numbers, has the wrong shape, or is out of range (naming the components).
        """
        E = np.atleast_1d(_numbers("E", E))
        if E.ndim != 1 or E.size == 0:
            raise SampleError(f"materials: E must be a non-empty 1-D list of Young's moduli, got shape {E.shape}")
        out = {}
        for name, val in [("E", E), ("nu", nu), ("tensile_strength", tensile_strength),
                          ("shear_strength", shear_strength)]:
            arr = _numbers(name, val)
            try:
                arr = np.broadcast_to(arr, E.shape).copy()
            except ValueError:
                raise SampleError(
                    f"materials: {name} has shape {arr.shape}, expected a scalar or {E.shape[0]} values") from None
            if np.isnan(arr).any():
                raise SampleError(f"materials: {name} is NaN for components {listed(np.flatnonzero(np.isnan(arr)))}")
            out[name] = arr
        bad = np.flatnonzero(~np.isfinite(out["E"]) | (out["E"] <= 0))
        if bad.size:
            raise SampleError(f"materials: E must be finite and > 0; bad components {listed(bad)}")
        bad = np.flatnonzero(~((out["nu"] > -1.0) & (out["nu"] < 0.5)))
        if bad.size:
            raise SampleError(f"materials: nu must lie in (-1, 0.5); bad components {listed(bad)}")
        for name in ("tensile_strength", "shear_strength"):
            bad = np.flatnonzero(out[name] <= 0)
            if bad.size:
                raise SampleError(f"materials: {name} must be > 0; bad components {listed(bad)}")
        return cls(**out)


_register(BondMaterials, ["E", "nu", "tensile_strength", "shear_strength"])


@dataclasses.dataclass(frozen=True)
class ParticleMaterial:
    """Properties of the particle material (used by contacts and for mass).

    density [kg/m^3], E: Young's modulus for Hertz contacts [Pa], nu: Poisson ratio [-],
    friction: Coulomb coefficient [-], restitution: coefficient of restitution for contact damping [-].
    """

    density: Any = 2500.0
    E: Any = 1.0e9
    nu: Any = 0.25
    friction: Any = 0.5
    restitution: Any = 0.5

    @classmethod
    def create(cls, **kw) -> "ParticleMaterial":
        """Build and check the particle material; fields not given take the class defaults.

        Args:
          **kw: ``density`` [kg/m^3] > 0, ``E`` [Pa] > 0, ``nu`` in (-1, 0.5), ``friction`` >= 0, ``restitution`` in
            (0, 1]; each a finite real scalar.

        Returns:
          The material, fields as float64 scalars.

        Raises:
          SampleError: an unknown field, a value that is not a real number, or one out of range.
        """
        unknown = set(kw) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise SampleError(f"particle_material: unknown fields {sorted(map(str, unknown))}")
        values = {}
        for k, v in {**dataclasses.asdict(cls()), **kw}.items():
            arr = np.asarray(v) if not isinstance(v, (str, bytes)) else None
            if arr is None or arr.shape != () or arr.dtype == bool or not (
                    np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
                raise SampleError(f"particle_material: {k} must be a real number, got {shown(v)}")
            try:
                values[k] = np.float64(arr)
            except OverflowError:
                raise SampleError(f"particle_material: {k} must be a real number, got {shown(v)}") from None
        pm = cls(**values)
        checks = {
            "density": pm.density > 0, "E": pm.E > 0, "nu": -1 < pm.nu < 0.5,
            "friction": pm.friction >= 0, "restitution": 0 < pm.restitution <= 1,
        }
        ranges = {"density": "> 0 [kg/m^3]", "E": "> 0 [Pa]", "nu": "in (-1, 0.5)", "friction": ">= 0",
                  "restitution": "in (0, 1]"}
        for name, ok in checks.items():
            if not (ok and np.isfinite(getattr(pm, name))):
                raise SampleError(f"particle_material: {name}={float(getattr(pm, name))!r} is out of range (must "
                                  f"be finite and {ranges[name]})")
        return pm


_register(ParticleMaterial, ["density", "E", "nu", "friction", "restitution"])


_BOND_CONTACT = ("superimpose", "replace")


@dataclasses.dataclass(frozen=True)
class Sample:
    """A bonded-particle sample (a JAX pytree), of spheres (3D) or of discs (2D).

    Particles (``n``): ``positions [n, 3]`` m, ``radii [n]`` m, ``mass [n]`` kg, ``inertia [n]`` kg m^2
    (solid sphere, 2/5 m r^2).
    Bonds (``nb``): ``bonds [nb, 2]`` particle indices (i < j), ``bond_radius [nb]`` m, ``bond_material [nb]``
    component index, ``bond_length [nb]`` initial length L m, ``bond_area [nb]`` A = pi r_b^2,
    ``bond_I [nb]`` I = pi r_b^4 / 4, ``bond_J [nb]`` J = pi r_b^4 / 2.
    A two-dimensional sample (:attr:`dim` 2) has ``positions [n, 2]``: discs of ``thickness`` t (mass
    rho pi r^2 t, inertia m r^2 / 2) and bonds of rectangular cross-section 2 r_b x t (A = 2 r_b t,
    I = (2 r_b)^3 t / 12; see :mod:`jaxbpm._geometry`).
    ``materials``: :class:`BondMaterials` (per component). ``particle_material``: :class:`ParticleMaterial`.
    ``types [n]`` int32: each particle's type (LAMMPS atom types, another code's material or group column; default
    1), which boundary groups can select (:class:`jaxbpm.scenes.groups.Type`); no solver reads it.
    Static: ``bond_contact`` (``"superimpose"``: bonded pairs also feel contact forces, or ``"replace"``: they do
    not), ``domain`` (the generated region, or ``None``).

    Build it with :meth:`from_arrays`; the plain constructor does no checking.
    """

    positions: Any
    radii: Any
    mass: Any
    inertia: Any
    bonds: Any
    bond_radius: Any
    bond_material: Any
    bond_length: Any
    bond_area: Any
    bond_I: Any
    bond_J: Any
    materials: BondMaterials
    particle_material: ParticleMaterial
    bond_contact: str = "superimpose"
    domain: Domain | None = None
    types: Any = None
    thickness: float | None = None

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_arrays(
        cls,
        positions,
        radii,
        bonds,
        bond_radius=None,
        *,
        bond_radius_ratio: float | None = None,
        bond_material=None,
        materials: Mapping[str, Any] | BondMaterials | None = None,
        density: float | None = None,
        particle_material: Mapping[str, Any] | ParticleMaterial | None = None,
        bond_contact: str = "superimpose",
        domain: Domain | None = None,
        types=None,
        wide_bonds: bool = False,
        thickness: float | None = None,
    ) -> "Sample":
        """Build and validate a sample from plain arrays.

        Args:
          positions: ``[n, 3]`` sphere centres, or ``[n, 2]`` disc centres: a two-dimensional sample [m].
          radii: ``[n]`` (or a scalar) particle radii [m].
          bonds: ``[nb, 2]`` integer particle indices; the order within a pair does not matter.
          bond_radius: ``[nb]`` or scalar bond radius [m]. Give this or ``bond_radius_ratio``.
          bond_radius_ratio: bond radius as a fraction of the smaller particle's radius.
          bond_material: ``[nb]`` component index per bond (default all 0).
          materials: ``{"E": [...], "nu": [...], "tensile_strength": [...], "shear_strength": [...]}`` per
            component, or a :class:`BondMaterials`. Default: one component, E = 1 GPa, nu = 0.25, unbreakable.
          density: particle density [kg/m^3] (shortcut for ``particle_material={"density": ...}``).
          particle_material: mapping or :class:`ParticleMaterial` (contact E, nu, friction, restitution).
          bond_contact: ``"superimpose"`` or ``"replace"`` (do bonded pairs also feel contact forces?).
          domain: the region the sample fills (used for its packing fraction), optional.
          types: ``[n]`` (or a scalar) whole numbers >= 0, each particle's type (default 1, LAMMPS's first atom
            type); carried through subsets, renumbering and files, read by no solver.
          wide_bonds: allow bond radii above the smaller particle's radius (``bond_radius_ratio`` > 1), refused
            otherwise.
          thickness: the discs' thickness of a two-dimensional sample [m] (default 1 m, PFC2D's unit thickness);
            not for spheres.

        Returns:
          The sample, with its derived per-particle and per-bond quantities.

        Raises:
          SampleError: naming the problem and the offending indices.
        """
        pos = checked_positions(positions)
        n, dim = pos.shape
        t = checked_thickness(thickness, dim)
        rad = checked_radii(radii, n)
        b = checked_bonds(bonds, n)
        length = bond_lengths(pos, rad, b)
        rb = checked_bond_radius(bond_radius, bond_radius_ratio, rad, b, wide_bonds=bool(wide_bonds))
        mats = _material_table(materials)
        bm = checked_bond_material(bond_material, b.shape[0], mats.n)
        pm = _particle_material(particle_material, density)
        if not isinstance(bond_contact, str) or bond_contact not in _BOND_CONTACT:
            raise SampleError(f"bond_contact must be one of {_BOND_CONTACT}, got {shown(bond_contact)}")
        domain = _checked_domain(domain, dim)
        ty = checked_types(types, n)

        mass, inertia = particle_mass(rad, float(pm.density), t)
        section = bond_section(rb, t)
        return cls(
            positions=pos,
            radii=rad,
            mass=mass,
            inertia=inertia,
            bonds=b,
            bond_radius=rb,
            bond_material=bm,
            bond_length=length,
            bond_area=section.area,
            bond_I=section.inertia,
            bond_J=section.polar,
            materials=mats,
            particle_material=pm,
            bond_contact=bond_contact,
            domain=domain,
            types=ty,
            thickness=t,
        )

    def replace(self, **changes) -> "Sample":
        """A new validated sample with some inputs of :meth:`from_arrays` changed.

        Args:
          **changes: keywords of :meth:`from_arrays` (``positions``, ``radii``, ``bonds``, ``bond_radius``,
            ``bond_radius_ratio``, ``bond_material``, ``materials``, ``density``, ``particle_material``,
            ``bond_contact``, ``domain``, ``types``, ``wide_bonds``, ``thickness``). New ``bonds`` need a new
            ``bond_radius`` or ``bond_radius_ratio``. The bond radii are checked against the radii again only where
            one of them changes.

        Returns:
          The sample, its derived quantities recomputed.

        Raises:
          SampleError: an unknown keyword, or inputs that make no valid sample.
        """
        kw = dict(positions=self.positions, radii=self.radii, bonds=self.bonds, bond_radius=self.bond_radius,
                  bond_material=self.bond_material, materials=self.materials,
                  particle_material=self.particle_material, bond_contact=self.bond_contact, domain=self.domain,
                  types=self.types, thickness=self.thickness)
        if "bond_radius_ratio" in changes:
            kw.pop("bond_radius")
        if "bonds" in changes and "bond_radius" not in changes and "bond_radius_ratio" not in changes:
            raise SampleError("replace(bonds=...) also needs bond_radius or bond_radius_ratio for the new bonds")
        if "bonds" in changes and "bond_material" not in changes:
            kw.pop("bond_material")
        unknown = set(changes) - set(kw) - {"bond_radius_ratio", "density", "wide_bonds"}
        if unknown:
            raise SampleError(f"replace: unknown fields {sorted(unknown)}")
        kw["wide_bonds"] = not {"radii", "bonds", "bond_radius", "bond_radius_ratio"} & set(changes)
        kw.update(changes)
        return Sample.from_arrays(**kw)

    def subset(self, keep) -> "Sample":
        """The sample restricted to some of its particles, with the bonds between them.

        Args:
          keep: ``[n]`` booleans, True for the particles kept (at least one).

        Returns:
          The smaller sample; particles and bonds keep their order.

        Raises:
          SampleError: ``keep`` has the wrong shape or keeps nothing.
        """
        keep = np.asarray(keep, bool)
        if keep.shape != (self.n_particles,):
            raise SampleError(f"subset: keep must have shape [{self.n_particles}], got {keep.shape}")
        if not keep.any():
            raise SampleError("subset: no particle kept")
        new_index = np.cumsum(keep) - 1
        b = np.asarray(self.bonds)
        kb = keep[b[:, 0]] & keep[b[:, 1]]
        return self._rebuilt(keep, new_index[b[kb]], kb)

    def renumbered(self, order=None) -> "Sample":
        """The same sample with its particles renumbered.

        The generators already number their particles along a Morton curve; samples read from other codes' files
        keep the files' order unless renumbered.

        Args:
          order: ``[n]`` permutation: particle ``k`` of the result is particle ``order[k]`` of this one. Default:
            along a Morton space-filling curve (:func:`jaxbpm.generate.morton_order`), so that particles close in
            space are close in memory and the solvers' gathers and scatters stay in cache.

        Returns:
          The renumbered sample; bonds follow their particles and are sorted by their first particle.

        Raises:
          SampleError: ``order`` is not a permutation of the particle indices.
        """
        order = morton_order(self.positions) if order is None else np.asarray(order)
        n = self.n_particles
        if order.shape != (n,) or not np.array_equal(np.sort(order), np.arange(n)):
            raise SampleError(f"renumbered: order must be a permutation of the {n} particle indices")
        new_index = np.empty(n, np.int64)
        new_index[order] = np.arange(n)
        b = np.sort(new_index[np.asarray(self.bonds, np.int64).reshape(-1, 2)], axis=1)
        by = np.lexsort((b[:, 1], b[:, 0]))
        return self._rebuilt(order, b[by], by)

    def _rebuilt(self, rows, bonds, bond_rows) -> "Sample":
        """The particles ``rows`` of this sample (their types with them) and its bonds ``bond_rows``, now joining
        ``bonds``, validated again."""
        pick = lambda a, idx: None if a is None else np.asarray(a)[idx]  # noqa: E731
        return Sample.from_arrays(pick(self.positions, rows), pick(self.radii, rows), bonds,
                                  pick(self.bond_radius, bond_rows), bond_material=pick(self.bond_material, bond_rows),
                                  materials=self.materials, particle_material=self.particle_material,
                                  bond_contact=self.bond_contact, domain=self.domain, types=pick(self.types, rows),
                                  wide_bonds=True,  # (bonds of this sample, accepted when it was built)
                                  thickness=self.thickness)

    def largest_cluster(self) -> "Sample":
        """The sample without the particles outside its largest bonded cluster (loose particles and fragments).

        Returns:
          The largest cluster as a sample (:meth:`subset`).
        """
        labels = self.clusters()
        return self.subset(labels == np.argmax(np.bincount(labels)))

    # ------------------------------------------------------------------ derived info
    @property
    def n_particles(self) -> int:
        """The number of particles ``n``."""
        return int(np.shape(self.positions)[0])

    @property
    def dim(self) -> int:
        """The spatial dimension: positions are ``[n, dim]`` (3: spheres, three rotations each; 2: discs in the
        x-y plane, one rotation each)."""
        return int(np.shape(self.positions)[1])

    @property
    def n_bonds(self) -> int:
        """The number of bonds ``nb``."""
        return int(np.shape(self.bonds)[0])

    @property
    def n_materials(self) -> int:
        """The number of bond material components."""
        return self.materials.n

    def coordination(self) -> np.ndarray:
        """The number of bonds of each particle.

        Returns:
          ``[n]`` integer counts.
        """
        b = np.asarray(self.bonds)
        return np.bincount(b.ravel(), minlength=self.n_particles)

    def clusters(self, joined=None) -> np.ndarray:
        """The cluster label of each particle: particles joined by bonds share a label.

        Args:
          joined: ``[k, 2]`` more pairs of particle indices joined as by bonds (particles in contact, say), or
            ``None``.

        Returns:
          ``[n]`` integer labels, 0 to the number of clusters - 1.
        """
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        n, b = self.n_particles, np.asarray(self.bonds, np.int64).reshape(-1, 2)
        if joined is not None:
            b = np.concatenate([b, np.asarray(joined, np.int64).reshape(-1, 2)])
        graph = coo_matrix((np.ones(len(b)), (b[:, 0], b[:, 1])), shape=(n, n))
        return connected_components(graph, directed=False)[1]

    def packing_fraction(self) -> tuple[float, str]:
        """Solid volume over the sample's volume (2D: disc area over the sample's area), and what that volume is.

        Returns:
          ``(fraction, basis)``: the fraction, over the generated ``domain`` when known (basis ``"box domain"`` or
          ``"cylinder domain"``), else over the bounding box of the particles (``"bounding box of the spheres"``,
          or ``"... of the discs"``).
        """
        rad, pos = np.asarray(self.radii), np.asarray(self.positions)
        solid = solid_measure(rad, self.dim)
        if self.domain is not None:
            return solid / self.domain.volume, f"{self.domain.kind} domain"
        size = (pos + rad[:, None]).max(axis=0) - (pos - rad[:, None]).min(axis=0)
        return solid / float(np.prod(size)), f"bounding box of the {'discs' if self.dim == 2 else 'spheres'}"

    def summary(self) -> SampleSummary:
        """Counts, coordination, clusters, packing fraction and extent of the sample.

        Returns:
          A :class:`SampleSummary` (``str()`` gives a readable table).
        """
        coord = self.coordination()
        labels = self.clusters()
        sizes = np.bincount(labels)
        pos, rad = np.asarray(self.positions), np.asarray(self.radii)
        phi, basis = self.packing_fraction()
        return SampleSummary(
            n_particles=self.n_particles,
            n_bonds=self.n_bonds,
            n_materials=self.n_materials,
            bonds_per_material=tuple(int(c) for c in np.bincount(np.asarray(self.bond_material),
                                                                 minlength=self.n_materials)),
            coordination_mean=float(coord.mean()),
            coordination_min=int(coord.min()),
            coordination_max=int(coord.max()),
            n_unbonded=int(np.sum(coord == 0)),
            n_clusters=int(sizes.size),
            largest_cluster=int(sizes.max()),
            packing_fraction=phi,
            packing_basis=basis,
            bbox_lo=tuple(float(v) for v in (pos - rad[:, None]).min(axis=0)),
            bbox_hi=tuple(float(v) for v in (pos + rad[:, None]).max(axis=0)),
            radius_min=float(rad.min()),
            radius_mean=float(rad.mean()),
            radius_max=float(rad.max()),
            total_mass=float(np.sum(self.mass)),
            bond_contact=self.bond_contact,
            types=tuple((int(t), int(c)) for t, c in zip(*np.unique(np.asarray(self.types), return_counts=True))),
        )

    def __repr__(self) -> str:
        flat = "" if self.dim == 3 else f", dim=2, thickness={self.thickness!r}"
        return (f"Sample(n_particles={self.n_particles}, n_bonds={self.n_bonds}, "
                f"n_materials={self.n_materials}, bond_contact={self.bond_contact!r}{flat})")


_register(
    Sample,
    ["positions", "radii", "mass", "inertia", "bonds", "bond_radius", "bond_material", "bond_length",
     "bond_area", "bond_I", "bond_J", "materials", "particle_material", "types"],
    ["bond_contact", "domain", "thickness"],
)


def _material_table(materials) -> BondMaterials:
    """The bond material table of :meth:`Sample.from_arrays`: a mapping, a :class:`BondMaterials` (checked again)
    or ``None`` (one component, E = 1 GPa, nu = 0.25, unbreakable)."""
    if materials is None:
        return BondMaterials.create(E=1.0e9)
    if isinstance(materials, BondMaterials):
        return BondMaterials.create(materials.E, materials.nu, materials.tensile_strength, materials.shear_strength)
    unknown = set(materials) - {"E", "nu", "tensile_strength", "shear_strength"}
    if unknown:
        raise SampleError(f"materials: unknown fields {sorted(unknown)}")
    if "E" not in materials:
        raise SampleError("materials: missing field 'E' (bond Young's modulus per component)")
    return BondMaterials.create(**materials)


def _particle_material(particle_material, density) -> ParticleMaterial:
    """The particle material of :meth:`Sample.from_arrays`: a mapping or a :class:`ParticleMaterial`, with
    ``density`` (when given) in place of its own."""
    if isinstance(particle_material, ParticleMaterial):
        pm_kw = {f.name: getattr(particle_material, f.name) for f in dataclasses.fields(ParticleMaterial)}
    else:
        pm_kw = dict(particle_material or {})
    if density is not None:
        pm_kw["density"] = density
    return ParticleMaterial.create(**pm_kw)


_DOMAIN_KINDS = ("box", "cylinder")


def _checked_domain(domain, dim: int = 3) -> Domain | None:
    """``domain`` as a :class:`Domain` of plain floats (``dim`` coordinates per corner), or a :class:`SampleError`
    saying what is wrong."""
    if domain is None:
        return None
    if not isinstance(domain, tuple) or len(domain) != 3:
        raise SampleError(f"domain must be a Domain(kind, lo, hi) or None, got {shown(domain)}")
    kind, lo, hi = domain
    if not isinstance(kind, str) or kind not in _DOMAIN_KINDS:
        raise SampleError(f"domain kind must be one of {_DOMAIN_KINDS}, got {shown(kind)}")
    try:
        lo_a, hi_a = (np.asarray(v, dtype=np.float64) for v in (lo, hi))
    except (TypeError, ValueError, OverflowError):
        raise SampleError(f"domain lo and hi must be {dim} numbers each [m], got {shown(lo)}, {shown(hi)}") from None
    if lo_a.shape != (dim,) or hi_a.shape != (dim,) or not (np.all(np.isfinite(lo_a)) and np.all(np.isfinite(hi_a))):
        raise SampleError(f"domain lo and hi must be {dim} finite numbers each [m] (the sample's dimension), got "
                          f"{shown(lo)}, {shown(hi)}")
    if not np.all(hi_a > lo_a):
        raise SampleError(f"domain hi must exceed lo in {'x and y' if dim == 2 else 'x, y and z'}, got lo "
                          f"{lo_a.tolist()}, hi {hi_a.tolist()}")
    return Domain(kind, tuple(lo_a.tolist()), tuple(hi_a.tolist()))
