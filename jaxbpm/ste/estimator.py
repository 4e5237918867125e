"""The STE's estimator: everything about a sample that does not depend on the bond parameters -- the interactions
(bonds, linearised contact candidates), each bond's stiffness per unit value of each stiffness (the Jacobian of the
bond law at rest), particle volumes, singular and surface particles, layers -- built once, in NumPy.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import capacity, put, setup_jit, size_class
from jaxbpm._geometry import check_three_d
from jaxbpm.errors import SampleError, SceneError
from jaxbpm.physics import tangent
from jaxbpm.physics.model import Model, contact_params
from jaxbpm.physics.padding import pad_model
from jaxbpm.sample import Sample
from jaxbpm.ste.options import boundary_keyword

__all__ = ["Estimator", "estimator", "clamped_form"]


_FABRIC_TOL = 1e-6


@dataclasses.dataclass(frozen=True)
class Estimator:
    """Everything the STE needs that does not depend on the bond parameters (build it with :func:`estimator`).

    model: the :class:`~jaxbpm.physics.model.Model` of the bonds. pairs ``[P, 2]``: interacting pairs, the
    ``nb`` bonds first, then the active contacts; d ``[P, 3]``: ``x_j - x_i`` at rest; contact_d ``[C, 3]``: the
    contact vectors shortened to their linearisation overlap. volume ``[n]``: V^n [m^3]; valid ``[n]``: not
    singular; include ``[n]``: valid, not clamped and not at the free surface (enters the averages); free ``[n]``:
    valid and not clamped by the scene (its fluctuation is solved for; a clamped particle follows the affine field, ``phi = 0``).
    layer ``[n]``: layer index of each particle along the scene axis (for ``layered``). With ``dofs=3``: geometry
    ``[S, nb, 9]``, the bond's ``K^nm`` (row-major 3x3) per unit value of each stiffness that enters it (``terms``,
    indices into (k_n, k_t, k_tw, k_b)): the Jacobian of the bond law at rest is linear in the stiffnesses, so
    ``K^nm = sum_s k_s geometry[s]``; contact_k ``[C, 9]``: the contacts' ``K^nm`` (parameter-free).
    layer_count: the number of layers (``n_layers`` or fewer: the padding's are empty). counts ``[3]``: the real
    numbers of particles, bonds and contacts (the arrays may be padded to a size class, see :func:`estimator`).
    Static: ``dofs`` (3 or 6), ``first_neighbour``, ``n_layers`` (layer capacity), ``axis``, ``terms``.
    """

    model: Model
    pairs: Any
    d: Any
    contact_d: Any
    contact_radii: Any
    contact_params: Any
    volume: Any
    valid: Any
    include: Any
    layer: Any
    geometry: Any = None
    contact_k: Any = None
    layer_count: Any = None
    counts: Any = None
    free: Any = None
    dofs: int = 3
    first_neighbour: bool = False
    n_layers: int = 1
    axis: int = 2
    terms: tuple = ()

    @property
    def n(self) -> int:
        """Rows of the particle arrays (with the padding)."""
        return int(self.volume.shape[0])

    @property
    def particles(self) -> int:
        """Number of real particles."""
        return self.n if self.counts is None else int(self.counts[0])

    @property
    def bonds(self) -> int:
        """Number of real bonds."""
        return self.n_bonds if self.counts is None else int(self.counts[1])

    @property
    def contacts(self) -> int:
        """Number of real active contacts."""
        return self.n_contacts if self.counts is None else int(self.counts[2])

    @property
    def n_bonds(self) -> int:
        return int(self.model.bonds.shape[0])

    @property
    def n_contacts(self) -> int:
        return int(self.contact_d.shape[0])

    @property
    def skipped(self) -> int:
        """Number of singular particles left out (the padding not counted)."""
        return self.particles - int(np.sum(np.asarray(self.valid)))

    @property
    def relaxing(self):
        """``[n]`` mask of the particles whose fluctuation is solved for (``free``; ``valid`` when not set)."""
        return self.valid if self.free is None else self.free

    @property
    def clamped(self) -> int:
        """Number of non-singular particles the scene clamps (they follow the affine field)."""
        return int(np.sum(np.asarray(self.valid) & ~np.asarray(self.relaxing)))

    @property
    def surface(self) -> int:
        """Number of non-singular, not clamped surface particles left out of the averages."""
        return int(np.sum(np.asarray(self.relaxing) & ~np.asarray(self.include)))


jax.tree_util.register_dataclass(
    Estimator, data_fields=["model", "pairs", "d", "contact_d", "contact_radii", "contact_params", "volume", "valid",
                            "include", "layer", "geometry", "contact_k", "layer_count", "counts", "free"],
    meta_fields=["dofs", "first_neighbour", "n_layers", "axis", "terms"])


def estimator(sample: Sample, scene=None, *, dofs: int = 3, first_neighbour: bool = False, contacts=None,
              contact_fraction: float | None = None, layer_thickness: float | None = None,
              surface_depth: float | None = None, volumes=None, precision: str = "float64",
              pad: bool = False, boundary: str = "clamped", clamp_layers: bool | None = None) -> Estimator:
    """Build the parameter-independent part of the STE for ``sample`` (and ``scene``, optional).

    Args:
      sample: the bonded sample.
      scene: a :class:`~jaxbpm.scenes.UniaxialCompression` or ``None``; it sets the load axis, whether contacts are
        linearised (``scene.contacts``) and the target strain at which they are, and the clamped particles.
      boundary: ``"clamped"`` (default): the particles the scene clamps (boundary ``"layers"`` or
        ``fixed``/``driven`` masks) follow the affine field (no fluctuation), as their prescribed displacements do
        in the DEM and the DSM; they bound the sample along the load, so they are left out of the averages and
        ``surface_depth`` counts from the faces parallel to the load only. Exact where the affine field is (a
        clamped simple-cubic lattice, to round-off). ``"free"``: the paper's form, every particle relaxes (the
        clamped ones as one-sided surface particles) and ``surface_depth`` counts from every face. Without a scene,
        or with walls (which clamp no particle), the free form is built.
      clamp_layers: the deprecated spelling of ``boundary`` (``True``: ``"clamped"``, ``False``: ``"free"``;
        :class:`DeprecationWarning`).
      dofs: 3 (translations, the paper's form) or 6 (translations and rotations) per particle. A two-dimensional
        sample takes the translations-only form (2 DOF per disc; the estimator's ``dofs`` is then 2).
      first_neighbour: the first-neighbour-only form (Eq. 33-35) instead of Eq. 32.
      contacts: override ``scene.contacts``.
      contact_fraction: fraction of the target strain at which contacts are linearised (default: middle of the
        scene's fit range).
      layer_thickness: layer thickness of the layered model [m] (default two mean particle diameters).
      surface_depth: particles closer than this to the sample's free surface [m] are left out of the averages
        (default one mean particle diameter; 0 keeps every non-singular particle that is not clamped).
      volumes: ``[n]`` particle volumes V^n [m^3] to use instead of particle volume / global solid fraction.
      precision: ``"float64"`` (default) or ``"float32"``: the float type of the estimate's arithmetic. The
        geometry is always built in the float type JAX gives (float64 with x64 on) and then cast. float32 runs the
        estimate faster and moves it by ~1e-7 relative; reverse-mode gradients lose more (the backward pass sums
        terms that cancel), and finite differences drown in rounding: calibrate with float64 (the default).
      pad: pad particles, pairs and layers to their size class (:func:`jaxbpm._compile.size_class`) so that samples
        of similar size share compiled programs. Padding particles are singular (no interaction, zero volume),
        padding pairs have zero stiffness: every result is that of the unpadded estimator (the local tensors and
        layers of the padding are extra rows, NaN and empty). ``est.counts`` holds the real counts.

    Raises:
      SceneError / SampleError: bad options, or a sample with no interactions.
    """
    if not isinstance(sample, Sample):
        raise TypeError(f"sample must be a jaxbpm.Sample, got {type(sample).__name__}")
    if dofs not in (3, 6):
        raise SceneError(f"dofs must be 3 or 6 per particle, got {dofs!r}")
    if sample.dim == 2:  # discs: the translations-only form, 2 DOF each
        if dofs == 6:
            check_three_d(sample, "the STE with rotations (dofs=6)")
        dofs = 2
    if precision not in ("float64", "float32"):
        raise SceneError(f"precision must be 'float64' or 'float32', got {precision!r}")
    axis = 2 if scene is None else int(scene.axis)
    use_contacts = (scene is not None and bool(scene.contacts)) if contacts is None else bool(contacts)
    if sample.dim == 2 and use_contacts:
        check_three_d(sample, "the STE with contacts")
    model = _bond_model(sample, dofs)
    pairs, d, cpairs, cd = _interactions(sample, model, scene, axis, use_contacts, contact_fraction)
    valid = _non_singular(pairs, d, sample.n_particles)
    parts = _particles(sample, scene, valid, boundary_keyword(boundary, clamp_layers), volumes, surface_depth)
    layer, n_layers = _layers(sample, axis, _layer_thickness(sample, layer_thickness))
    counts = np.array([sample.n_particles, len(sample.bonds), len(cpairs)], np.int64)
    rad = np.asarray(sample.radii, np.float64)
    arrays = dict(pairs=pairs, d=d, cd=cd, crad=rad[cpairs].reshape(-1, 2), layer=layer, **parts)
    layers_cap = n_layers
    if pad:
        model, arrays = _padded(model, arrays, counts)
        layers_cap = capacity(n_layers, minimum=4)
    est = _assemble(sample, model, arrays, counts, n_layers, layers_cap, dofs, first_neighbour, axis,
                    getattr(scene, "linear_law", None))
    if precision == "float32":
        f32 = jnp.float32
        est = dataclasses.replace(est, d=est.d.astype(f32), volume=est.volume.astype(f32),
                                  geometry=None if est.geometry is None else est.geometry.astype(f32),
                                  contact_k=None if est.contact_k is None else est.contact_k.astype(f32))
    return est


def _interactions(sample, model, scene, axis, use_contacts, contact_fraction):
    """``(pairs [P, 2], d [P, 3], contact pairs [C, 2], contact vectors [C, 3])``: the bonds, then the contacts
    active at the linearisation point (their vectors shortened to the linearisation overlap)."""
    pos = np.asarray(sample.positions, np.float64)
    cpairs = np.zeros((0, 2), np.int64)
    cd = np.zeros((0, pos.shape[1]))
    if use_contacts:
        if scene is None:
            raise SceneError("contacts need a scene (its axis and target strain set the linearisation overlap)")
        frac = float(np.mean(scene.fit_range)) if contact_fraction is None else float(contact_fraction)
        if not (0 < frac <= 1):
            raise SceneError(f"contact_fraction must lie in (0, 1], got {contact_fraction!r}")
        cpairs, cd = _active_contacts(sample, model, axis, frac * scene.strain)
    bonds = np.asarray(sample.bonds, np.int64)
    pairs = np.concatenate([bonds, cpairs]).astype(np.int32)
    if len(pairs) == 0:
        raise SampleError("STE: the sample has no bonds (and no contacts): there is no stiffness to estimate")
    d = np.concatenate([pos[bonds[:, 1]] - pos[bonds[:, 0]], pos[cpairs[:, 1]] - pos[cpairs[:, 0]]])
    return pairs, d, cpairs, cd


def _non_singular(pairs, d, n) -> np.ndarray:
    """``[n]``: the particles with at least three interactions, not all coplanar (smallest fabric eigenvalue above
    :data:`_FABRIC_TOL` of the largest); in 2D at least two, not all collinear."""
    dim = d.shape[1]
    unit = d / np.linalg.norm(d, axis=1, keepdims=True)
    ends = pairs.T.ravel()  # both ends of every pair: per-component bincounts (np.add.at is several times slower)
    fabric = np.stack([np.bincount(ends, np.tile(unit[:, a] * unit[:, b], 2), minlength=n)
                       for a in range(dim) for b in range(dim)], axis=1).reshape(n, dim, dim)
    count = np.bincount(ends, minlength=n)
    eig = np.linalg.eigvalsh(fabric)
    return (count >= dim) & (eig[:, 0] > _FABRIC_TOL * np.maximum(eig[:, -1], 1e-300))


def clamped_form(scene, boundary: str) -> bool:
    """Whether the STE of ``scene`` with ``boundary`` clamps the scene's particles (``"clamped"`` on a scene with
    clamped particles: layers or masks, not walls).

    Args:
      scene: the scene or ``None``.
      boundary: ``"clamped"`` or ``"free"``.

    Returns:
      ``True`` for the clamped form, ``False`` for the free one.
    """
    return boundary == "clamped" and scene is not None and not scene.uses_walls


def _particles(sample, scene, valid, boundary, volumes, surface_depth) -> dict:
    """The per-particle arrays ``[n]``: ``valid``, ``free`` (valid and not clamped by the scene), ``vol`` (V^n)
    and ``include`` (valid, not clamped and at least ``surface_depth`` inside the sample's free surface)."""
    n = sample.n_particles
    rad = np.asarray(sample.radii, np.float64)
    # particles the scene clamps (its fixed and driven sets) have prescribed displacements: they follow the affine
    # field (no fluctuation), as in the DEM and the DSM, instead of relaxing as free one-sided surface particles;
    # they are the sample's boundary along the load, so the free surface is the faces parallel to the load
    clamped = np.zeros(n, bool)
    along = None
    if clamped_form(scene, boundary):
        fixed, driven = scene.layers(sample)
        clamped, along = fixed | driven, int(scene.axis)
    if volumes is None:
        phi, _ = sample.packing_fraction()
        solid = 4.0 / 3.0 * np.pi * rad**3 if sample.dim == 3 else np.pi * rad**2 * sample.thickness
        vol = solid / phi
    else:
        vol = np.asarray(volumes, np.float64)
        if vol.shape != (n,) or not np.all(np.isfinite(vol) & (vol > 0)):
            raise SceneError(f"volumes must be [{n}] finite positive particle volumes, got shape {vol.shape}")
    depth = 2.0 * float(np.mean(rad)) if surface_depth is None else float(surface_depth)
    if not (depth >= 0 and np.isfinite(depth)):
        raise SceneError(f"surface_depth must be a length >= 0, got {surface_depth!r}")
    include = valid & ~clamped
    if depth > 0:
        include &= _boundary_distance(sample, along) >= depth
    if not include.any():
        raise SceneError(f"STE: no particle is non-singular ({int(valid.sum())} are), not clamped "
                         f"({int(clamped.sum())} are) and deeper than surface_depth = {depth:.4g} m inside the "
                         "sample's free surface; use a smaller surface_depth")
    return {"valid": valid, "free": valid & ~clamped, "vol": vol, "include": include}


def _layer_thickness(sample, layer_thickness) -> float:
    """The layered model's layer thickness [m] (default two mean particle diameters)."""
    h = 4.0 * float(np.mean(sample.radii)) if layer_thickness is None else float(layer_thickness)
    if not (h > 0 and np.isfinite(h)):
        raise SceneError(f"layer_thickness must be a positive length, got {layer_thickness!r}")
    return h


def _padded(model, arrays: dict, counts):
    """The model and the arrays padded to their size class: padding particles are singular (no interaction, zero
    volume), padding pairs join the two first padding particles with zero stiffness, padding contacts do not
    touch."""
    n, nb, nc = (int(c) for c in counts)
    n_cap, nb_cap, nc_cap = size_class(n, nb, nc)
    model = pad_model(model, n_cap, nb_cap)
    pairs, d = arrays["pairs"], arrays["d"]
    # padding pairs join the two first padding particles along x with zero stiffness
    pad_pair = np.array([[n, n + 1]], np.int32)
    pairs = np.concatenate([pairs[:nb], np.repeat(pad_pair, nb_cap - nb, 0), pairs[nb:],
                            np.repeat(pad_pair, nc_cap - nc, 0)])
    pp = np.asarray(model.positions0)
    gap = pp[n + 1:n + 2] - pp[n:n + 1]  # the padding bonds' vector (zero stiffness)
    d = np.concatenate([d[:nb], np.repeat(gap, nb_cap - nb, 0), d[nb:], np.repeat(gap, nc_cap - nc, 0)])
    r_pad = np.full((nc_cap - nc, 2), 0.25 * float(np.linalg.norm(gap)))
    cd = np.concatenate([arrays["cd"], np.repeat(gap, nc_cap - nc, 0)])  # twice the sum of their radii apart
    extra = n_cap - n
    out = dict(pairs=pairs, d=d, cd=cd, crad=np.concatenate([arrays["crad"], r_pad]),
               vol=np.concatenate([arrays["vol"], np.zeros(extra)]),
               layer=np.concatenate([arrays["layer"], np.zeros(extra, np.int32)]))
    for name in ("valid", "include", "free"):
        out[name] = np.concatenate([arrays[name], np.zeros(extra, bool)])
    return model, out


def _assemble(sample, model, a: dict, counts, n_layers, layers_cap, dofs, first_neighbour, axis,
              linear=None) -> Estimator:
    """The :class:`Estimator` of the (padded) arrays ``a``; with 3 DOF each bond's ``K^nm`` per unit stiffness and
    the contacts' ``K^nm`` (Hertz-Mindlin's, or with a :class:`~jaxbpm.physics.linear.LinearLaw` the linear law's),
    without a Coulomb limit."""
    dtype = model.positions0.dtype
    pm = sample.particle_material
    if linear is None:
        cparams = contact_params(float(pm.E), float(pm.nu), float("inf"), float(pm.restitution), dtype.name, False)
    else:
        cparams = linear.params(pm, dtype)._replace(friction=jnp.asarray(np.inf, dtype))
    est = Estimator(model=model, pairs=put(a["pairs"]), d=put(a["d"], dtype), contact_d=put(a["cd"], dtype),
                    contact_radii=put(a["crad"], dtype).reshape(-1, 2), contact_params=cparams,
                    volume=put(a["vol"], dtype), valid=put(a["valid"]), include=put(a["include"]),
                    free=put(a["free"]), layer=put(a["layer"], np.int32), layer_count=put(n_layers, np.int32),
                    counts=counts, dofs=int(dofs), first_neighbour=bool(first_neighbour), n_layers=int(layers_cap),
                    axis=axis)
    if dofs == model.dim:  # translations only
        nc, nc_cap = int(counts[2]), int(a["cd"].shape[0])
        geometry, terms = _bond_geometry(model)
        ck = (-np.asarray(_contact_jacobians_jit(est))[:, :3, 3:].reshape(-1, 9) if nc_cap else
              np.zeros((0, dofs * dofs)))
        ck[nc:] = 0.0  # padding contacts do not touch; their stiffness is zero to the last bit
        est = dataclasses.replace(est, geometry=geometry, terms=terms, contact_k=jnp.asarray(ck, dtype))
    return est


def _bond_model(sample: Sample, dofs: int) -> Model:
    from jaxbpm.physics.model import build_model

    return build_model(sample, contacts=False, walls=None, rotations=dofs == 6)  # (2D: dofs 2, no rotations)


def _domain_extent(sample: Sample, axis: int) -> tuple[float, float]:
    if sample.domain is not None:
        return float(sample.domain.lo[axis]), float(sample.domain.hi[axis])
    z, r = np.asarray(sample.positions)[:, axis], np.asarray(sample.radii)
    return float((z - r).min()), float((z + r).max())


def _boundary_distance(sample: Sample, along: int | None = None) -> np.ndarray:
    """Distance of each particle centre to the boundary of the sample's domain (box or z-cylinder), or to its
    spheres' bounding box; with ``along`` (an axis) to the faces parallel to it only (a cylinder's curved face
    counts whole, its flat faces where they are parallel to ``along``)."""
    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    if sample.domain is not None:
        lo, hi = np.asarray(sample.domain.lo), np.asarray(sample.domain.hi)
    else:
        lo, hi = (pos - rad[:, None]).min(axis=0), (pos + rad[:, None]).max(axis=0)
    dist = np.minimum(pos - lo, hi - pos)
    if along is not None:
        dist[:, along] = np.inf
    if sample.domain is not None and sample.domain.kind == "cylinder":
        centre, radius = 0.5 * (lo[:2] + hi[:2]), 0.25 * float(np.sum(hi[:2] - lo[:2]))
        radial = radius - np.linalg.norm(pos[:, :2] - centre, axis=1)
        return radial if sample.dim == 2 else np.minimum(radial, dist[:, 2])
    return dist.min(axis=1)


def _layers(sample: Sample, axis: int, h: float) -> tuple[np.ndarray, int]:
    lo, hi = _domain_extent(sample, axis)
    n_layers = max(1, int(round((hi - lo) / h)))
    z = np.asarray(sample.positions)[:, axis]
    layer = np.clip(np.floor((z - lo) / (hi - lo) * n_layers), 0, n_layers - 1).astype(np.int32)
    return layer, n_layers


def _active_contacts(sample: Sample, model: Model, axis: int, strain: float):
    """Candidate pairs that touch under the affine ``strain`` along ``axis``, and their shortened vectors."""
    from scipy.spatial import cKDTree

    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    reach = 2.0 * rad.max() * (1.0 + strain) + 1e-12
    pairs = np.array(sorted(cKDTree(pos).query_pairs(reach)), dtype=np.int64).reshape(-1, 2)
    if sample.bond_contact == "replace" and len(pairs):
        pairs = pairs[~np.asarray(model.bonded(jnp.asarray(pairs, jnp.int32)))]
    d = pos[pairs[:, 1]] - pos[pairs[:, 0]]
    dist = np.linalg.norm(d, axis=1)
    gap = dist - rad[pairs[:, 0]] - rad[pairs[:, 1]]
    overlap = strain * d[:, axis] ** 2 / np.maximum(dist, 1e-300) - gap
    keep = overlap > 0
    d, dist, overlap = d[keep], dist[keep], overlap[keep]
    # the pair vector shortened so that the spheres overlap by `overlap` (their rest gap closed as well)
    d_lin = d * ((rad[pairs[keep, 0]] + rad[pairs[keep, 1]] - overlap) / dist)[:, None]
    return pairs[keep], d_lin


_unit_jacobians = setup_jit(tangent.bond_unit)


def _bond_geometry(model: Model) -> tuple[jnp.ndarray, tuple]:
    """``K^nm`` of every bond at rest (3 DOF, ``[S, nb, 9]``) per unit value of each stiffness that enters it.

    ``K^nm = d f^n / d u^m`` is ``jax.jacfwd`` of the bond law with respect to the bond vector (3 DOF: the law sees
    the displacements only through ``d = r0 + u^j - u^i``, and ``f_j = -f_i``), evaluated once per stiffness with
    that stiffness set to one and the others to zero; the law is linear in its stiffnesses, so any parameter set
    gives ``K^nm = sum_s k_s G_s``. Terms that vanish identically (twisting and bending without rotations) are
    dropped.
    """
    r0 = model.r0
    nb = int(r0.shape[0])
    if nb == 0:
        return jnp.zeros((0, 0, 9), r0.dtype), ()
    g = _unit_jacobians(r0)  # kept on the device: only which terms are nonzero comes to the host
    terms = tuple(int(s) for s in np.flatnonzero(np.asarray(jnp.any(g != 0, axis=(1, 2)))))
    return (g if len(terms) == g.shape[0] else g[np.array(terms, int)]), terms


def _contact_jacobians(est: Estimator) -> jnp.ndarray:
    """Per-contact stiffness ``[C, 2nd, 2nd]`` at the linearisation overlap
    (:func:`jaxbpm.physics.tangent.contact_full`)."""
    return tangent.contact_full(est.contact_d, est.contact_radii, est.contact_params, est.dofs)


_contact_jacobians_jit = setup_jit(_contact_jacobians)
