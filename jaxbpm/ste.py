"""Stiffness tensor estimation (STE): the elastic tensor of a bonded sample without computing any displacement.

After Misra & Chang, as in Jarolin & Dosta 2020 (section 3.2, Eq. 11-36). Every interaction (bond, and linearised Hertz
contact
when the scene has contacts) gets its stiffness as the Jacobian of the SAME force law the DEM and the DSM use,
evaluated at rest (``jax.jacfwd``); nothing is written twice. With ``dofs=3`` (the paper's form) a pair's stiffness
is the 3x3 block ``K^nm = d f^n / d u^m`` (force on n per displacement of m); with ``dofs=6`` the fluctuations also
carry the particle rotations and each pair contributes 6x6 blocks (the same algebra, one size up).

For a displacement gradient ``G`` (affine field ``u = G x``) each particle n relaxes by a fluctuation ``phi^n``
with its neighbours m held (Eq. 20-29)::

    D^n      = sum_m H^nn_m                               self-stiffness of n (3x3: sum_m K^nm)
    Gamma^n  = (D^n)^-1 sum_m K^nm G d^nm                 Eq. 23 (d^nm = x^m - x^n)
    Gamma^^n = (D^n)^-1 sum_m K^nm Gamma^m                Eq. 24 with Eq. 29 (second neighbours held)
    f^nm     = K^nm G d^nm - H^nn_m phi^n + K^nm phi^m    force on n from m
    sigma^n  = 1 / (2 V^n) sum_m d^nm (x) f^nm            Eq. 12  ->  C^n (Eq. 32)

Full form (Eq. 32, as the authors computed it): ``phi^n = Gamma^n + Gamma^^n``, ``phi^m = Gamma^m`` (the
neighbour's own second-order term Gamma^^m is neglected). First-neighbour form (Eq. 33-35,
``first_neighbour=True``): ``phi^n = Gamma^n``, ``phi^m = 0``. The full form is the better estimate for
homogeneous samples (it relaxes more); with strong stiffness contrasts between neighbouring bonds its second-order
terms overshoot (a band of 100x softer bonds can even give a negative modulus), and the first-neighbour form, which
stays between the affine bound and zero, is the one to use.

Conventions and choices:

* **Tensor indices.** ``C[i, j, k, l] = d sigma_ij / d G_lk`` (the paper's ``d_i K_jl d_k``). The stress of Eq. 12
  is not symmetric when the interactions resist rigid rotation (3 DOF shear springs), so the *local* and *body*
  tensors are returned minor-symmetrised (stress and strain are symmetric); :func:`raw_body_tensor` gives the
  unsymmetrised one. Averaged over all particles, Eq. 32 has the major symmetry by construction (checked by the
  tests); the per-particle tensors of the full form have it only approximately (Gamma^^ mixes neighbours).
* **Voigt order** ``(11, 22, 33, 23, 13, 12)``, engineering shear strains: ``sigma_I = C_IJ eps_J``.
* **Particle volume** ``V^n`` = particle volume / global solid fraction (solid volume over the sample's domain
  volume, or over the spheres' bounding box without a domain), so ``sum_n V^n`` = the sample volume. The body
  tensor is the V-weighted average of the local ones, in which V^n cancels: ``C = sum_n sum_m d (x) f / (2 V)``.
* **Surface particles.** A particle whose centre lies within ``surface_depth`` (default one mean particle
  diameter) of the sample's boundary (its domain box or cylinder, else the spheres' bounding box) has a one-sided
  neighbourhood: Eq. 32 lets it relax as if the missing neighbours were absent, which under-counts the stiffness of
  the bulk (by 15-20 % on a 1500-particle box). Such particles keep their local tensor and their Gamma (they still
  act on their neighbours) but are left out of the averages; ``surface_depth=0`` averages over every particle, as
  the paper did for samples of 10^5 particles.
* **Singular particles** (fewer than three interactions, or all their interactions coplanar: the fabric
  ``sum n n^T`` has a smallest eigenvalue below 1e-6 of its largest) are skipped: they have no local tensor and do
  not enter the averages, and as neighbours they follow the affine field (``Gamma^m = 0``). Their count is reported.
* **Contacts** (scene with ``contacts=True``) are linearised at a small overlap, since Hertz stiffness vanishes at
  zero overlap: the overlap each candidate pair reaches under the affine target strain of the scene at the middle
  of its fit range, ``delta = s (d . e)^2 / |d| eps - gap`` (``s`` = mid fit range, default 0.625; ``e`` the load
  axis). Pairs that do not touch by then are left out; no slip (the Coulomb limit is lifted, as in the static DSM).
* **Walls** (Jarolin & Dosta 2020, 3.2.3): the body and each wall act as springs in series; a wall's stiffness is the
sum of the
  tangent stiffnesses of the particles touching it (gap below half the target displacement), each at its share of
  the force the sample carries at mid fit range (solved for self-consistently).
* **Layered springs in series** (``layered=True``, Jarolin & Dosta 2020 Case 3): the sample is cut into layers two mean
  particle diameters thick along the load; each layer's modulus comes from the V-weighted mean tensor of its
  particles, its cross-section from the volume they represent (``sum V^n / h``), and the layers add as springs in
  series over the gauge length.

Everything that depends on the bond parameters is vectorised (per-interaction Jacobians, ``segment_sum`` per
particle, batched 3x3 / 6x6 inverses), differentiable and ``vmap``-able over parameter sets; neighbour searches and
the choice of interactions are done once, in NumPy, when the :class:`Estimator` is built. With 3 DOF (the default)
the Estimator also holds each bond's ``K^nm`` per unit stiffness (``jax.jacfwd`` of the bond law, which is linear
in its stiffnesses), so a parameter set costs ``K^nm = k_n G_n + k_t G_t`` per bond, and the algebra runs on the
pairs (one 3x3 block each) with the body tensor as a few matrix products over pairs and particles; the cost is
linear in the number of bonds.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import Program, SetupCache, capacity, compile_clock, put, size_class, traced
from jaxbpm.errors import SampleError, SceneError
from jaxbpm.physics import bond as bond_mod
from jaxbpm.physics import contact as contact_mod
from jaxbpm.physics import rotation
from jaxbpm.physics.model import Model, _contact_params, default_params
from jaxbpm.physics.padding import pad_model
from jaxbpm.sample import Sample

__all__ = [
    "Estimator", "estimator", "pair_stiffness", "local_tensors", "body_tensor", "raw_body_tensor", "voigt",
    "tensor_from_voigt", "moduli", "directional_modulus", "isotropic_fit", "layer_stiffness", "wall_series",
    "SceneGeometry", "scene_geometry", "scene_stiffness", "stiffness_function", "solve_scene", "LocalMap", "local_map",
    "VOIGT",
]

VOIGT = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
"""Index pairs of the Voigt components, in order."""

_FABRIC_TOL = 1e-6


# ---------------------------------------------------------------------------------------------------- setup
@dataclasses.dataclass(frozen=True)
class Estimator:
    """Everything the STE needs that does not depend on the bond parameters (build it with :func:`estimator`).

    model: the :class:`~jaxbpm.physics.model.Model` of the bonds. pairs ``[P, 2]``: interacting pairs, the
    ``nb`` bonds first, then the active contacts; d ``[P, 3]``: ``x_j - x_i`` at rest; contact_d ``[C, 3]``: the
    contact vectors shortened to their linearisation overlap. volume ``[n]``: V^n [m^3]; valid ``[n]``: not
    singular; include ``[n]``: valid and not at the surface (enters the averages). layer ``[n]``: layer index of
    each particle along the scene axis (for ``layered``). With ``dofs=3``: geometry ``[S, nb, 9]``, the bond's
    ``K^nm`` (row-major 3x3) per unit value of each stiffness that enters it (``terms``, indices into
    (k_n, k_t, k_tw, k_b)): the Jacobian of the bond law at rest is linear in the stiffnesses, so
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
    def surface(self) -> int:
        """Number of non-singular surface particles left out of the averages."""
        return int(np.sum(np.asarray(self.valid) & ~np.asarray(self.include)))


jax.tree_util.register_dataclass(
    Estimator, data_fields=["model", "pairs", "d", "contact_d", "contact_radii", "contact_params", "volume", "valid",
                            "include", "layer", "geometry", "contact_k", "layer_count", "counts"],
    meta_fields=["dofs", "first_neighbour", "n_layers", "axis", "terms"])


def estimator(sample: Sample, scene=None, *, dofs: int = 3, first_neighbour: bool = False, contacts=None,
              contact_fraction: float | None = None, layer_thickness: float | None = None,
              surface_depth: float | None = None, volumes=None, precision: str = "float64",
              pad: bool = False) -> Estimator:
    """Build the parameter-independent part of the STE for ``sample`` (and ``scene``, optional).

    Args:
      sample: the bonded sample.
      scene: a :class:`~jaxbpm.scenes.UniaxialCompression` or ``None``; it sets the load axis, whether contacts are
        linearised (``scene.contacts``) and the target strain at which they are.
      dofs: 3 (translations, the paper's form) or 6 (translations and rotations) per particle.
      first_neighbour: the first-neighbour-only form (Eq. 33-35) instead of Eq. 32.
      contacts: override ``scene.contacts``.
      contact_fraction: fraction of the target strain at which contacts are linearised (default: middle of the
        scene's fit range).
      layer_thickness: layer thickness of the layered model [m] (default two mean particle diameters).
      surface_depth: particles closer than this to the sample's boundary [m] are left out of the averages
        (default one mean particle diameter; 0 keeps every non-singular particle).
      volumes: ``[n]`` particle volumes V^n [m^3] to use instead of particle volume / global solid fraction.
      precision: ``"float64"`` (default) or ``"float32"``: the float type of the estimate's arithmetic. The
        geometry is always built in the float type JAX gives (float64 with x64 on) and then cast. float32 runs the
        estimate 2-3x faster on CPU and moves it by ~1e-7 relative (the estimate itself is 5-20 % from the DEM);
        reverse-mode gradients lose more (~2e-3 relative on a 1k-particle packing: the backward pass sums terms
        that cancel), and finite differences drown in rounding: calibrate with float64 (the default).
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
    if precision not in ("float64", "float32"):
        raise SceneError(f"precision must be 'float64' or 'float32', got {precision!r}")
    axis = 2 if scene is None else int(scene.axis)
    use_contacts = bool(getattr(scene, "contacts", False)) if contacts is None else bool(contacts)
    pos, rad = np.asarray(sample.positions, np.float64), np.asarray(sample.radii, np.float64)
    n = sample.n_particles
    model = _bond_model(sample, dofs)
    dtype = model.positions0.dtype

    # contacts active at the linearisation point
    cpairs = np.zeros((0, 2), np.int64)
    cd = np.zeros((0, 3))
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

    # singular particles: fewer than three interactions, or coplanar ones (smallest fabric eigenvalue ~ 0)
    unit = d / np.linalg.norm(d, axis=1, keepdims=True)
    fabric = np.zeros((n, 3, 3))
    outer = unit[:, :, None] * unit[:, None, :]
    np.add.at(fabric, pairs[:, 0], outer)
    np.add.at(fabric, pairs[:, 1], outer)
    count = np.bincount(pairs.ravel(), minlength=n)
    eig = np.linalg.eigvalsh(fabric)
    valid = (count >= 3) & (eig[:, 0] > _FABRIC_TOL * np.maximum(eig[:, -1], 1e-300))

    if volumes is None:
        phi, _ = sample.packing_fraction()
        vol = 4.0 / 3.0 * np.pi * rad**3 / phi
    else:
        vol = np.asarray(volumes, np.float64)
        if vol.shape != (n,) or not np.all(np.isfinite(vol) & (vol > 0)):
            raise SceneError(f"volumes must be [{n}] finite positive particle volumes, got shape {vol.shape}")

    depth = 2.0 * float(np.mean(rad)) if surface_depth is None else float(surface_depth)
    if not (depth >= 0 and np.isfinite(depth)):
        raise SceneError(f"surface_depth must be a length >= 0, got {surface_depth!r}")
    include = valid & (_boundary_distance(sample) >= depth) if depth > 0 else valid
    if not include.any():
        raise SceneError(f"STE: no particle is both non-singular ({int(valid.sum())} are) and deeper than "
                         f"surface_depth = {depth:.4g} m inside the sample; use a smaller surface_depth")

    h = 4.0 * float(np.mean(rad)) if layer_thickness is None else float(layer_thickness)
    if not (h > 0 and np.isfinite(h)):
        raise SceneError(f"layer_thickness must be a positive length, got {layer_thickness!r}")
    layer, n_layers = _layers(sample, axis, h)

    nb, nc = len(bonds), len(cpairs)
    counts = np.array([n, nb, nc], np.int64)
    n_cap, nb_cap, nc_cap, layers_cap = n, nb, nc, n_layers
    if pad:
        n_cap, nb_cap, nc_cap = size_class(n, nb, nc)
        layers_cap = capacity(n_layers, minimum=4)
        model = pad_model(model, n_cap, nb_cap)
        # padding pairs join the two first padding particles along x with zero stiffness
        pad_pair = np.array([[n, n + 1]], np.int32)
        pairs = np.concatenate([pairs[:nb], np.repeat(pad_pair, nb_cap - nb, 0), pairs[nb:],
                                np.repeat(pad_pair, nc_cap - nc, 0)])
        pp = np.asarray(model.positions0)
        gap = pp[n + 1:n + 2] - pp[n:n + 1]  # the padding bonds' vector (zero stiffness)
        d = np.concatenate([d[:nb], np.repeat(gap, nb_cap - nb, 0), d[nb:], np.repeat(gap, nc_cap - nc, 0)])
        r_pad = np.full((nc_cap - nc, 2), 0.25 * float(np.linalg.norm(gap)))
        cd = np.concatenate([cd, np.repeat(gap, nc_cap - nc, 0)])  # twice the sum of their radii apart: no touch
        crad = np.concatenate([rad[cpairs].reshape(-1, 2), r_pad])
        extra = n_cap - n
        vol, valid, include = (np.concatenate([vol, np.zeros(extra)]), np.concatenate([valid, np.zeros(extra, bool)]),
                               np.concatenate([include, np.zeros(extra, bool)]))
        layer = np.concatenate([layer, np.zeros(extra, np.int32)])
    else:
        crad = rad[cpairs].reshape(-1, 2)

    pm = sample.particle_material
    cparams = _contact_params(float(pm.E), float(pm.nu), float("inf"), float(pm.restitution), dtype.name, False)
    est = Estimator(model=model, pairs=put(pairs), d=put(d, dtype), contact_d=put(cd, dtype),
                    contact_radii=put(crad, dtype).reshape(-1, 2), contact_params=cparams, volume=put(vol, dtype),
                    valid=put(valid), include=put(include), layer=put(layer, np.int32),
                    layer_count=put(n_layers, np.int32), counts=counts, dofs=int(dofs),
                    first_neighbour=bool(first_neighbour), n_layers=int(layers_cap), axis=axis)
    if dofs == 3:
        geometry, terms = _bond_geometry(model)
        ck = (-np.asarray(_contact_jacobians_jit(est))[:, :3, 3:].reshape(-1, 9) if nc_cap else np.zeros((0, 9)))
        ck[nc:] = 0.0  # padding contacts do not touch; their stiffness is zero to the last bit
        est = dataclasses.replace(est, geometry=geometry, terms=terms, contact_k=jnp.asarray(ck, dtype))
    if precision == "float32":
        f32 = jnp.float32
        est = dataclasses.replace(est, d=est.d.astype(f32), volume=est.volume.astype(f32),
                                  geometry=None if est.geometry is None else est.geometry.astype(f32),
                                  contact_k=None if est.contact_k is None else est.contact_k.astype(f32))
    return est


def _bond_model(sample: Sample, dofs: int) -> Model:
    from jaxbpm.physics.model import build_model

    return build_model(sample, contacts=False, walls=None, rotations=dofs == 6)


def _domain_extent(sample: Sample, axis: int) -> tuple[float, float]:
    if sample.domain is not None:
        return float(sample.domain.lo[axis]), float(sample.domain.hi[axis])
    z, r = np.asarray(sample.positions)[:, axis], np.asarray(sample.radii)
    return float((z - r).min()), float((z + r).max())


def _boundary_distance(sample: Sample) -> np.ndarray:
    """Distance of each particle centre to the boundary of the sample's domain (box or z-cylinder), or to its
    spheres' bounding box."""
    pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
    if sample.domain is not None:
        lo, hi = np.asarray(sample.domain.lo), np.asarray(sample.domain.hi)
    else:
        lo, hi = (pos - rad[:, None]).min(axis=0), (pos + rad[:, None]).max(axis=0)
    dist = np.minimum(pos - lo, hi - pos)
    if sample.domain is not None and sample.domain.kind == "cylinder":
        centre, radius = 0.5 * (lo[:2] + hi[:2]), 0.25 * float(np.sum(hi[:2] - lo[:2]))
        radial = radius - np.linalg.norm(pos[:, :2] - centre, axis=1)
        return np.minimum(radial, dist[:, 2])
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


# ---------------------------------------------------------------------------------------------------- stiffness
@jax.jit
def _unit_jacobians(r0):
    """``[4, nb, 9]``: ``d f_i / d d`` of every bond at rest with (k_n, k_t, k_tw, k_b) = each unit vector."""
    q = jnp.array([1.0, 0.0, 0.0, 0.0], r0.dtype)

    def one(r, s):
        k = [jnp.where(s == t, 1.0, 0.0).astype(r.dtype) for t in range(4)]
        return jax.jacfwd(lambda d: bond_mod.bond_law(d, r, q, q, *k).f_i)(r).reshape(9)

    return jnp.stack([jax.vmap(one, (0, None))(r0, s) for s in range(4)])


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
    g = np.asarray(_unit_jacobians(r0))
    terms = tuple(s for s in range(4) if np.any(g[s] != 0))
    return put(g[np.array(terms, int)]), terms


def _bond_jacobians(est: Estimator, params) -> jnp.ndarray:
    """Per-bond stiffness ``[nb, 2nd, 2nd]`` at rest, DOF order (u_i, theta_i, u_j, theta_j): minus the Jacobian of
    the bond law (the same function the DEM and the DSM integrate)."""
    model = est.model
    k = model.stiffness(params)
    nd = est.dofs

    def one(r0, kn, kt, ktw, kb):
        def f(z):
            ui, uj = z[:3], z[nd:nd + 3]
            if nd == 6:
                qi, qj = rotation.from_rotation_vector(z[3:6]), rotation.from_rotation_vector(z[9:12])
            else:
                qi = qj = jnp.array([1.0, 0.0, 0.0, 0.0], r0.dtype)
            out = bond_mod.bond_law(r0 + uj - ui, r0, qi, qj, kn, kt, ktw, kb)
            parts = [out.f_i, out.m_i, -out.f_i, out.m_j] if nd == 6 else [out.f_i, -out.f_i]
            return jnp.concatenate(parts)

        return -jax.jacfwd(f)(jnp.zeros(2 * nd, r0.dtype))

    return jax.vmap(one)(model.r0, k.kn, k.kt, k.ktw, k.kb)


def _contact_jacobians(est: Estimator) -> jnp.ndarray:
    """Per-contact stiffness ``[C, 2nd, 2nd]``: minus the Jacobian of the Hertz-Mindlin law (no slip, empty spring)
    at the linearisation overlap."""
    nd = est.dofs
    p = est.contact_params
    dtype = est.contact_d.dtype

    def one(d0, radii):
        ri, rj = radii[0], radii[1]

        def f(z):
            ui, uj = z[:3], z[nd:nd + 3]
            d = d0 + uj - ui
            dxi = uj - ui
            if nd == 6:
                nrm = d0 / jnp.linalg.norm(d0)
                dxi = dxi + jnp.cross(z[9:12], -rj * nrm) - jnp.cross(z[3:6], ri * nrm)
            zero = jnp.zeros(3, dtype)
            out = contact_mod.hertz_mindlin(d, ri, rj, 1.0, 1.0, zero, dxi, zero, p)
            parts = [out.f_i, out.m_i, -out.f_i, out.m_j] if nd == 6 else [out.f_i, -out.f_i]
            return jnp.concatenate(parts)

        return -jax.jacfwd(f)(jnp.zeros(2 * nd, dtype))

    return jax.vmap(one)(est.contact_d, est.contact_radii)


_contact_jacobians_jit = jax.jit(_contact_jacobians)


def pair_stiffness(est: Estimator, params) -> jnp.ndarray:
    """Stiffness ``[P, 2nd, 2nd]`` of every interaction (bonds, then contacts) at rest, global frame.

    The 3x3 block ``[:3, nd:nd+3]`` with its sign flipped is ``K^nm`` of the paper (force on i per displacement of j).
    """
    jac = _bond_jacobians(est, params)
    if est.n_contacts:
        jac = jnp.concatenate([jac, _contact_jacobians(est).astype(jac.dtype)])
    return jac


class _Edges(NamedTuple):
    src: Any   # [E] particle n
    dst: Any   # [E] neighbour m
    d: Any     # [E, 3] d^nm = x^m - x^n
    h_nn: Any  # [E, nd, nd] self block of the interaction on n
    k_nm: Any  # [E, nd, nd] coupling: generalised force on n per DOF of m (K^nm)


def _edges(est: Estimator, params) -> _Edges:
    jac = pair_stiffness(est, params)
    nd = est.dofs
    i, j = est.pairs[:, 0], est.pairs[:, 1]
    jac = jac.astype(est.d.dtype)
    return _Edges(src=jnp.concatenate([i, j]), dst=jnp.concatenate([j, i]), d=jnp.concatenate([est.d, -est.d]),
                  h_nn=jnp.concatenate([jac[:, :nd, :nd], jac[:, nd:, nd:]]),
                  k_nm=-jnp.concatenate([jac[:, :nd, nd:], jac[:, nd:, :nd]]))


def _edge_forces(est: Estimator, params) -> tuple[_Edges, jnp.ndarray]:
    """Edges and the force on n of each edge per unit displacement gradient, ``f [E, 3, 3, 3]`` (j; l, k)."""
    e = _edges(est, params)
    n, nd = est.n, est.dofs
    valid = est.valid
    eye = jnp.eye(nd, dtype=e.d.dtype)
    D = jax.ops.segment_sum(e.h_nn, e.src, n)
    D = jnp.where(valid[:, None, None], D, eye)
    A = jnp.linalg.inv(D)
    # affine load: generalised force on n per G_lk, sum_m K^nm[:, l] d_k
    B = jax.ops.segment_sum(e.k_nm[:, :, :3, None] * e.d[:, None, None, :], e.src, n)
    gamma = jnp.where(valid[:, None, None, None], jnp.einsum("nab,nblk->nalk", A, B), 0.0)  # Eq. 23
    affine = e.k_nm[:, :3, :3, None] * e.d[:, None, None, :]
    if est.first_neighbour:
        phi_n = gamma
        f = affine - jnp.einsum("eja,ealk->ejlk", e.h_nn[:, :3, :], phi_n[e.src])
    else:
        gamma_m = gamma[e.dst]
        hat = jax.ops.segment_sum(jnp.einsum("eab,eblk->ealk", e.k_nm, gamma_m), e.src, n)
        hat = jnp.where(valid[:, None, None, None], jnp.einsum("nab,nblk->nalk", A, hat), 0.0)  # Eq. 24 + 29
        phi_n = gamma + hat
        f = (affine - jnp.einsum("eja,ealk->ejlk", e.h_nn[:, :3, :], phi_n[e.src])
             + jnp.einsum("eja,ealk->ejlk", e.k_nm[:, :3, :], gamma_m))
    return e, f


# Three DOF per particle (the paper's form, the default): every pair has one coupling block K = K^nm = d f^i / d u^j
# (the same for both directions; the self block of the pair on either end is K as well). The algebra below is written
# on [P, ...] rows of the pairs and [n, ...] rows of the particles: broadcast products summed term by term
# (elementwise loops, no tiny batched matrix products, which XLA on CPU runs one small dot at a time), per-particle
# sums as scatters of materialised rows, and every sum over all pairs or particles that the body tensor needs as one
# matrix product with the pairs (particles) as the contracted dimension.
def _mul(a, b):
    """``[..., p, q] x [..., q, r] -> [..., p, r]`` as a sum of ``q`` broadcast products."""
    out = a[..., :, 0, None] * b[..., None, 0, :]
    for c in range(1, a.shape[-1]):
        out = out + a[..., :, c, None] * b[..., None, c, :]
    return out


def _gram(a, b):
    """``a^T b`` for ``a [m, p]``, ``b [m, q]`` (the long axis ``m`` contracted)."""
    return jax.lax.dot_general(a, b, (((0,), (0,)), ((), ())))


def _inverse3(D):
    """Inverse of ``[n, 3, 3]`` matrices by cofactors (elementwise)."""
    a = [[D[:, r, c] for c in range(3)] for r in range(3)]
    cof = [[a[(r + 1) % 3][(c + 1) % 3] * a[(r + 2) % 3][(c + 2) % 3]
            - a[(r + 1) % 3][(c + 2) % 3] * a[(r + 2) % 3][(c + 1) % 3] for c in range(3)] for r in range(3)]
    inv_det = 1.0 / (a[0][0] * cof[0][0] + a[0][1] * cof[0][1] + a[0][2] * cof[0][2])
    return jnp.stack([jnp.stack([cof[c][r] * inv_det for c in range(3)], axis=-1) for r in range(3)], axis=1)


def _coupling(est: Estimator, params) -> jnp.ndarray:
    """``K^nm [P, 3, 3]`` of every pair (3 DOF): ``sum_s k_s G_s`` for the bonds, then the contacts."""
    k = est.model.stiffness(params)
    ks = tuple(jnp.asarray(x).astype(est.d.dtype) for x in (k.kn, k.kt, k.ktw, k.kb))
    nb = est.n_bonds
    K = jnp.zeros((nb, 9), est.d.dtype)
    for t, s in enumerate(est.terms):
        K = K + jnp.broadcast_to(ks[s], (nb,))[:, None] * est.geometry[t]
    if est.n_contacts:
        K = jnp.concatenate([K, est.contact_k.astype(K.dtype)])
    return K.reshape(-1, 3, 3)


class _Fluct3(NamedTuple):
    K: Any       # [P, 3, 3] K^nm
    B: Any       # [n, 3, 3, 3] sum_m K^nm[a, l] d^nm_k (a, l, k); also the lever sum M^n[i, j, a] = B[j, a, i]
    N: Any       # [n, 3, 3, 3] sum over the pairs into m of w^n d^nm_i K^nm[j, b] (i, j, b), weighted only
    gamma: Any   # [n, 3, 9] Gamma^n per G_lk (l * 3 + k)
    phi: Any     # [n, 3, 9] fluctuation of n
    q_i: Any     # [P, 3, 9] K Gamma^j (neighbour term on i), None in the first-neighbour form
    q_j: Any     # [P, 3, 9] K Gamma^i (neighbour term on j)


def _fluctuations3(est: Estimator, params, weighted: bool = False) -> _Fluct3:
    K = _coupling(est, params)
    n, d = est.n, est.d
    i, j = est.pairs[:, 0], est.pairs[:, 1]
    valid = est.valid[:, None, None]
    kd = (K[:, :, :, None] * d[:, None, None, :]).reshape(-1, 27)  # K[a, l] d_k
    rows = jnp.concatenate([K.reshape(-1, 9), kd], axis=1)
    s_i = jax.ops.segment_sum(rows, i, n)
    s_j = jax.ops.segment_sum(rows, j, n)  # d^nm = -d on the j end
    D = jnp.where(valid, (s_i[:, :9] + s_j[:, :9]).reshape(n, 3, 3), jnp.eye(3, dtype=d.dtype))
    B = (s_i[:, 9:] - s_j[:, 9:]).reshape(n, 3, 9)
    N = None
    if weighted and not est.first_neighbour:  # N^m: on m = j from the edge (i -> j), weight w^i; on i, -w^j
        w = est.include.astype(d.dtype)
        N = (jax.ops.segment_sum(w[i][:, None] * kd, j, n) - jax.ops.segment_sum(w[j][:, None] * kd, i, n))
        N = N.reshape(n, 3, 3, 3).transpose(0, 3, 1, 2)
    A = _inverse3(D)
    gamma = jnp.where(valid, _mul(A, B), 0.0)  # Eq. 23
    B = B.reshape(n, 3, 3, 3)
    if est.first_neighbour:
        return _Fluct3(K, B, N, gamma, gamma, None, None)
    q_i, q_j = _mul(K, gamma[j]), _mul(K, gamma[i])
    hat = (jax.ops.segment_sum(q_i.reshape(-1, 27), i, n) + jax.ops.segment_sum(q_j.reshape(-1, 27), j, n))
    hat = jnp.where(valid, _mul(A, hat.reshape(n, 3, 9)), 0.0)  # Eq. 24 + 29
    return _Fluct3(K, B, N, gamma, gamma + hat, q_i, q_j)


def _raw_body_tensor3(est: Estimator, params) -> jnp.ndarray:
    """``sum_n w^n sum_m d_i f^nm[j; l, k]`` with ``f^nm = K^nm G d - K phi^n + K Gamma^m``: the affine term as one
    matrix product over the pairs (both ends), the self term ``-w^n M^n phi^n`` and the neighbour term
    ``sum_m N^m Gamma^m`` (regrouped by the neighbour) over the particles."""
    fl = _fluctuations3(est, params, weighted=True)
    n, d = est.n, est.d
    i, j = est.pairs[:, 0], est.pairs[:, 1]
    w = est.include.astype(d.dtype)
    dd = ((w[i] + w[j])[:, None, None] * d[:, :, None] * d[:, None, :]).reshape(-1, 9)  # (i, k)
    t = jnp.dot(dd.T, fl.K.reshape(-1, 9)).reshape(3, 3, 3, 3).transpose(0, 2, 1, 3)
    # sum_n w B[j, a, i] phi[a, (l, k)] and sum_n N[i, j, b] Gamma[b, (l, k)]: one matrix product each that
    # contracts (particle, a) -- rows [n * 3, 9] on both sides (4x faster on CPU than per-particle products summed)
    bw = (w[:, None, None, None] * fl.B).transpose(0, 2, 3, 1).reshape(3 * n, 9)  # [(n, a), (i, j)]
    t = t - _gram(bw, fl.phi.reshape(3 * n, 9)).reshape(3, 3, 3, 3).transpose(0, 1, 3, 2)
    if fl.N is not None:
        nb_ = fl.N.transpose(0, 3, 1, 2).reshape(3 * n, 9)  # [(n, b), (i, j)]
        t = t + _gram(nb_, fl.gamma.reshape(3 * n, 9)).reshape(3, 3, 3, 3).transpose(0, 1, 3, 2)
    return t / (2.0 * jnp.sum(jnp.where(est.include, est.volume, 0.0)))


def _local_tensors3(est: Estimator, params) -> jnp.ndarray:
    fl = _fluctuations3(est, params)
    n, d = est.n, est.d
    i, j = est.pairs[:, 0], est.pairs[:, 1]
    kd = fl.K[:, :, :, None] * d[:, None, None, :]  # [P, j, l, k]
    g_i, g_j = kd, kd  # d_i f on the i end; on the j end (-d_i) (-K d + K Gamma^i) = d_i (K d - K Gamma^i)
    if fl.q_i is not None:
        g_i, g_j = kd + fl.q_i.reshape(-1, 3, 3, 3), kd - fl.q_j.reshape(-1, 3, 3, 3)

    def edge(g):
        return voigt(_symmetrise(d[:, :, None, None, None] * jnp.swapaxes(g, -2, -1)[:, None])).reshape(-1, 36)

    c = jax.ops.segment_sum(edge(g_i), i, n) + jax.ops.segment_sum(edge(g_j), j, n)
    s = jnp.einsum("njai,nalk->nijkl", fl.B, fl.phi.reshape(n, 3, 3, 3))
    c = c.reshape(n, 6, 6) - voigt(_symmetrise(s))
    return c / (2.0 * est.volume[:, None, None])


def _symmetrise(c):
    """Minor-symmetrise ``[..., 3, 3, 3, 3]``."""
    c = 0.5 * (c + jnp.swapaxes(c, -4, -3))
    return 0.5 * (c + jnp.swapaxes(c, -2, -1))


def raw_body_tensor(est: Estimator, params) -> jnp.ndarray:
    """The body tensor ``[3, 3, 3, 3]`` before minor symmetrisation: ``C[i,j,k,l] = d sigma_ij / d G_lk``, the
    V-weighted mean of Eq. 32 over the included particles (non-singular, not at the surface)."""
    if est.dofs == 3:
        return _raw_body_tensor3(est, params)
    return _raw_body_tensor_edges(est, params)


def _raw_body_tensor_edges(est: Estimator, params) -> jnp.ndarray:
    """:func:`raw_body_tensor` through the per-edge forces, for any ``dofs`` (the 6-DOF path; with 3 DOF the
    reference the pair form is checked against)."""
    e, f = _edge_forces(est, params)
    w = est.include[e.src].astype(f.dtype)
    t = jnp.einsum("ei,ejlk->ijkl", e.d * w[:, None], f)
    return t / (2.0 * jnp.sum(jnp.where(est.include, est.volume, 0.0)))


def body_tensor(est: Estimator, params) -> jnp.ndarray:
    """The body's stiffness in Voigt form ``[6, 6]`` [Pa]: V-weighted mean of the local tensors (Eq. 32), with
    the minor and major symmetries.

    Averaged over every particle, the mean of Eq. 32 is major-symmetric by construction; leaving out the singular
    and surface particles breaks that slightly (a fraction of a percent of the largest component on random
    packings), and that small antisymmetric part is removed here.
    """
    c6 = voigt(_symmetrise(raw_body_tensor(est, params)))
    return 0.5 * (c6 + c6.T)


def local_tensors(est: Estimator, params) -> jnp.ndarray:
    """Local stiffness tensors ``C^n`` in Voigt form ``[n, 6, 6]`` [Pa] (Eq. 32, or Eq. 33-35 with
    ``first_neighbour``), minor-symmetrised; NaN for singular (skipped) particles."""
    if est.dofs == 3:
        return jnp.where(est.valid[:, None, None], _local_tensors3(est, params), jnp.nan)
    return _local_tensors_edges(est, params)


_local_tensors_jit = jax.jit(local_tensors)


def _local_tensors_edges(est: Estimator, params) -> jnp.ndarray:
    e, f = _edge_forces(est, params)
    vi = np.array([p[0] for p in VOIGT])
    vj = np.array([p[1] for p in VOIGT])
    # edge contribution in Voigt form: sym_ij sym_kl d_i f_{j; l k}
    fs = 0.5 * (f + jnp.swapaxes(f, -2, -1))  # symmetric in (l, k)
    fs = fs[:, :, vj, vi]                       # [E, 3, 6]
    c = 0.5 * (e.d[:, vi, None] * fs[:, vj, :] + e.d[:, vj, None] * fs[:, vi, :])  # [E, 6, 6]
    c = jax.ops.segment_sum(c, e.src, est.n) / (2.0 * est.volume[:, None, None])
    return jnp.where(est.valid[:, None, None], c, jnp.nan)


def voigt(c) -> jnp.ndarray:
    """``[..., 3, 3, 3, 3]`` -> ``[..., 6, 6]`` (order 11, 22, 33, 23, 13, 12)."""
    i = np.array([p[0] for p in VOIGT])
    j = np.array([p[1] for p in VOIGT])
    return c[..., i[:, None], j[:, None], i[None, :], j[None, :]]


def tensor_from_voigt(c6) -> jnp.ndarray:
    """``[..., 6, 6]`` -> ``[..., 3, 3, 3, 3]`` with the minor symmetries."""
    idx = np.zeros((3, 3), int)
    for k, (a, b) in enumerate(VOIGT):
        idx[a, b] = idx[b, a] = k
    return c6[..., idx[:, :, None, None], idx[None, None, :, :]]


# ---------------------------------------------------------------------------------------------------- moduli
def moduli(c6) -> dict:
    """Engineering constants of a Voigt stiffness ``[..., 6, 6]``.

    Returns ``{"E": [..., 3]`` Young's moduli along x, y, z; ``"nu": [..., 3, 3]`` Poisson ratios nu_ij =
    -S_ij / S_ii (lateral strain j per axial strain i); ``"G": [..., 3]`` shear moduli G_23, G_13, G_12;
    ``"compliance": [..., 6, 6]}``.
    """
    s = jnp.linalg.inv(c6)
    diag = jnp.diagonal(s, axis1=-2, axis2=-1)
    return {"E": 1.0 / diag[..., :3], "nu": -s[..., :3, :3] / diag[..., :3, None], "G": 1.0 / diag[..., 3:],
            "compliance": s}


def directional_modulus(c6, direction) -> jnp.ndarray:
    """Young's modulus [Pa] along ``direction [3]`` (any length): ``1 / (b^T S b)``, ``b`` the Voigt form of
    ``n n^T`` with ``n`` the unit direction."""
    n = jnp.asarray(direction, c6.dtype)
    n = n / jnp.linalg.norm(n)
    b = jnp.stack([n[0] ** 2, n[1] ** 2, n[2] ** 2, n[1] * n[2], n[0] * n[2], n[0] * n[1]])
    return 1.0 / (b @ jnp.linalg.inv(c6) @ b)


def isotropic_fit(c6) -> tuple[jnp.ndarray, jnp.ndarray]:
    """``(E, nu)`` of the isotropic tensor nearest to ``c6`` (least squares over the 81 components)."""
    c = tensor_from_voigt(c6)
    a = jnp.einsum("...iijj->...", c)   # 9 lambda + 6 mu
    b = jnp.einsum("...ijij->...", c)   # 3 lambda + 12 mu
    mu = (3.0 * b - a) / 30.0
    lam = (a - 6.0 * mu) / 9.0
    return mu * (3.0 * lam + 2.0 * mu) / (lam + mu), lam / (2.0 * (lam + mu))


# ---------------------------------------------------------------------------------------------------- scenes
def layer_stiffness(est: Estimator, params, gauge_length, area):
    """Stiffness [N/m] of the layered springs-in-series model along ``est.axis`` (Jarolin & Dosta 2020, Case 3).

    Layer k: modulus ``E_k`` from the V-weighted mean tensor of its included particles (the body tensor where a
    layer has none), cross-section ``A_k = V_k / h`` from the volume its particles represent; compliance of the
    stack ``sum_k h / (E_k A_k)`` over the sample's extent, scaled to the gauge length. ``area`` is used only to
    keep the units when a layer holds no particle at all (it then counts with ``area``).
    """
    ax = est.axis
    c = local_tensors(est, params)
    w = jnp.where(est.include, est.volume, 0.0)
    cw = jnp.where(est.include[:, None, None], c, 0.0) * w[:, None, None]
    num = jax.ops.segment_sum(cw, est.layer, est.n_layers)
    wsum = jax.ops.segment_sum(w, est.layer, est.n_layers)
    vol = jax.ops.segment_sum(est.volume, est.layer, est.n_layers)
    body = body_tensor(est, params)
    c_layer = jnp.where(wsum[:, None, None] > 0, num / jnp.where(wsum > 0, wsum, 1.0)[:, None, None], body)
    e_layer = moduli(c_layer)["E"][:, ax]
    extent = jnp.sum(vol) / area  # the sample's extent along the axis, as the volume sees it
    count = jnp.asarray(est.n_layers if est.layer_count is None else est.layer_count, jnp.int32)
    h = extent / count.astype(vol.dtype)
    a_layer = jnp.where(vol > 0, vol / h, area)
    real = jnp.arange(est.n_layers, dtype=jnp.int32) < count  # layers beyond the count are padding
    compliance = jnp.sum(jnp.where(real, h / (e_layer * a_layer), 0.0)) * gauge_length / extent
    return 1.0 / compliance


class SceneGeometry(NamedTuple):
    """What the STE needs of a scene besides the estimator (a pytree; built on the host by
    :func:`scene_geometry`): gauge ``length`` [m], ``area`` [m^2], the compressive displacement ``load`` [m] at which
    the walls are linearised (``s`` x the target displacement, ``s`` the middle of the fit range), the
    ``wall_stiffness`` (E* [Pa] of a particle on a rigid wall, or k [N/m] for linear walls) and the masks ``[n]`` of
    the particles that touch the bottom and the top wall."""

    length: Any
    area: Any
    load: Any
    wall_stiffness: Any
    touch_bottom: Any
    touch_top: Any


def scene_geometry(est: Estimator, sample: Sample, scene, fraction: float | None = None):
    """``(SceneGeometry, wall_law)`` of ``scene`` on ``sample`` for ``est`` (``wall_law`` ``None`` without walls).
    NumPy work on the host; the masks have ``est.n`` rows (padding rows touch nothing)."""
    length, area = scene.geometry(sample)
    dtype = est.model.positions0.dtype
    n, law, ws = est.n, None, 0.0
    touch = [np.zeros(n, bool), np.zeros(n, bool)]
    s = float(np.mean(scene.fit_range)) if fraction is None else float(fraction)
    delta = scene.strain * length
    if scene.uses_walls:
        law = scene.wall_law
        pm = sample.particle_material
        if law == "hertz":
            ws = float(pm.E) / (1.0 - float(pm.nu) ** 2) if scene.wall_stiffness is None else scene.wall_stiffness
        elif law == "linear":
            if scene.wall_stiffness is None:
                raise SceneError("wall_law='linear' needs wall_stiffness [N/m]")
            ws = scene.wall_stiffness
        else:
            raise SceneError(f"unknown wall law {law!r}; use 'hertz' or 'linear'")
        ax = scene.axis
        pos, rad = np.asarray(sample.positions), np.asarray(sample.radii)
        m = len(rad)
        lo_gap = (pos[:, ax] - rad) - (pos[:, ax] - rad).min()
        hi_gap = (pos[:, ax] + rad).max() - (pos[:, ax] + rad)
        touch[0][:m], touch[1][:m] = lo_gap <= 0.5 * delta, hi_gap <= 0.5 * delta
    geo = SceneGeometry(length=put(length, dtype), area=put(area, dtype), load=put(s * delta, dtype),
                        wall_stiffness=put(ws, dtype), touch_bottom=put(touch[0]), touch_top=put(touch[1]))
    return geo, law


def _wall_series(k_body, radii, geo: SceneGeometry, law: str):
    dtype = jnp.result_type(k_body)
    ws = geo.wall_stiffness.astype(dtype)
    radii = radii.astype(dtype)

    def wall_k(force, touch):
        count = jnp.sum(touch.astype(dtype))
        if law == "linear":
            return ws * count + 0.0 * force
        share = force / count
        overlap = (3.0 * share / (4.0 * ws * jnp.sqrt(radii))) ** (2.0 / 3.0)
        return jnp.sum(jnp.where(touch, 2.0 * ws * jnp.sqrt(radii * overlap), 0.0))

    k = k_body
    kw = (k_body, k_body)
    load = geo.load.astype(dtype)
    for _ in range(40):  # k_wall ~ F^(1/3): a contraction, converges to round-off in a few dozen steps
        force = k * load
        kw = (wall_k(force, geo.touch_bottom), wall_k(force, geo.touch_top))
        k = 1.0 / (1.0 / k_body + 1.0 / kw[0] + 1.0 / kw[1])
    counts = [jnp.sum(t.astype(jnp.int32)) for t in (geo.touch_bottom, geo.touch_top)]
    return k, {"k_bottom": kw[0], "k_top": kw[1], "n_bottom": counts[0], "n_top": counts[1]}


def wall_series(k_body, est: Estimator, scene, sample: Sample, fraction: float | None = None):
    """The body and the two walls as springs in series (Jarolin & Dosta 2020, 3.2.3):
    ``1/K = 1/K_body + 1/k_bottom + 1/k_top``.

    A wall's stiffness is the sum of the tangent stiffnesses of the particles touching it, each carrying an equal
    share of the force ``F = K * s * delta`` the sample carries at the middle ``s`` of the scene's fit range
    (``delta`` = target displacement); ``K`` and ``F`` are solved for together (fixed point).
    Returns ``(K, {"k_bottom", "k_top", "n_bottom", "n_top"})``.
    """
    geo, law = scene_geometry(est, sample, scene, fraction)
    return _wall_series(k_body, est.model.radii, geo, law)


def _scene_stiffness(est: Estimator, params, geo: SceneGeometry, layered: bool, walls: str | None):
    c6 = body_tensor(est, params)
    e_axis = moduli(c6)["E"][est.axis]
    length, area = geo.length.astype(c6.dtype), geo.area.astype(c6.dtype)
    k_body = layer_stiffness(est, params, length, area) if layered else e_axis * area / length
    parts = {"K_body": k_body, "E_axis": e_axis, "tensor": c6}
    k = k_body
    if walls is not None:
        k, wall_parts = _wall_series(k_body, est.model.radii, geo, walls)
        parts.update(wall_parts)
    return k, parts


def scene_stiffness(est: Estimator, params, sample: Sample, scene, *, layered: bool = False):
    """Stiffness K [N/m] of ``scene`` from the STE: ``E_axis A / l`` (or the layered model), walls in series.

    Returns ``(K, parts)`` with ``parts = {"K_body", "E_axis", "tensor", ...}`` (jnp values). ``est.axis`` is the
    load axis (the estimator is built for the scene).
    """
    geo, law = scene_geometry(est, sample, scene)
    return _scene_stiffness(est, params, geo, layered, law)


def _check_scene(scene):
    from jaxbpm.scenes import UniaxialCompression

    if not isinstance(scene, UniaxialCompression):
        raise SceneError(f"the STE knows the UniaxialCompression scene, got {type(scene).__name__}")


def stiffness_function(sample: Sample, scene, *, layered: bool = False, pad: bool = True, **options):
    """A pure function ``params -> K`` [N/m] of ``scene`` estimated by the STE (``jit``/``grad``/``vmap``-able,
    e.g. ``jax.vmap(f)({"bond_E": E_batch, "bond_nu": nu_batch})``). ``options`` go to :func:`estimator`. The
    estimator is the one :func:`solve_scene` keeps for the sample (padded to its size class unless ``pad=False``),
    and a call with concrete parameters runs the program :func:`solve_scene` compiled (no compilation when the
    process solved a sample of that class before)."""
    _check_scene(scene)
    est, geo, law = _setups.get(sample, (scene, bool(pad), tuple(sorted(options.items()))),
                                lambda: _setup(sample, scene, pad, options))

    def stiffness(params):
        if not traced(params):
            return _solve_program(est, params, geo, layered=bool(layered), walls=law)[0][0]
        return _scene_stiffness(est, params, geo, layered, law)[0]

    return stiffness


def _outputs(est: Estimator, params, geo: SceneGeometry, layered: bool, walls: str | None):
    """Everything :func:`solve_scene` reports, from one program: K, its parts, the moduli and the isotropic fit."""
    k, parts = _scene_stiffness(est, params, geo, layered, walls)
    m = moduli(parts["tensor"])
    e_iso, nu_iso = isotropic_fit(parts["tensor"])
    return k, parts, m["E"], m["nu"], e_iso, nu_iso


_solve_program = Program(_outputs, static_argnames=("layered", "walls"))
_setups = SetupCache()


def _setup(sample, scene, pad, options):
    est = estimator(sample, scene, pad=pad, **options)
    return (est,) + scene_geometry(est, sample, scene)


def solve_scene(sample: Sample, scene, params=None, *, layered: bool = False, pad: bool = True, throw: bool = True,
                **options):
    """Estimate the stiffness of ``scene`` with the STE; see :func:`jaxbpm.solve` (``method="ste"``).

    pad: pad the estimator to its size class (:func:`estimator`), so that samples of similar size share one
    compiled program (the result is the same to round-off). throw: raise :class:`~jaxbpm.errors.NotFiniteError`
    when the stiffness is not finite (``False``: return the result with ``status="not_finite"``).
    ``stats``: ``tensor`` (Voigt 6x6 [Pa], nested lists), ``E_x``, ``E_y``, ``E_z`` [Pa], ``nu`` (3x3),
    ``E_iso``, ``nu_iso`` (isotropic fit), ``K_body`` (before walls), ``skipped`` (singular particles),
    ``surface`` (surface particles left out of the averages),
    ``particles``, ``bonds``, ``contacts``, ``dofs``, ``first_neighbour``, ``layered``; walls: ``k_bottom``,
    ``k_top`` [N/m], ``n_bottom``, ``n_top``; ``size_class`` (the padded particle, bond and contact capacities).
    """
    from jaxbpm.result import Result, settle

    t0 = time.perf_counter()
    _check_scene(scene)
    params = default_params(sample) if params is None else params
    _check_params(params, sample)
    with compile_clock() as setup_compile:  # programs the setup compiles count as compilation
        est, geo, law = _setups.get(sample, (scene, bool(pad), tuple(sorted(options.items()))),
                                    lambda: _setup(sample, scene, pad, options))
    setup_time = time.perf_counter() - t0 - setup_compile.seconds
    out, compile_time, run_time = _solve_program(est, params, geo, layered=bool(layered), walls=law)
    compile_time += setup_compile.seconds
    k, parts, e, nu, e_iso, nu_iso = jax.tree_util.tree_map(np.asarray, out)
    length, area = float(geo.length), float(geo.area)
    delta = scene.strain * length
    stats = {"tensor": parts["tensor"].tolist(), "E_x": float(e[0]), "E_y": float(e[1]), "E_z": float(e[2]),
             "nu": nu.tolist(), "E_iso": float(e_iso), "nu_iso": float(nu_iso), "K_body": float(parts["K_body"]),
             "E_axis": float(parts["E_axis"]), "skipped": est.skipped, "surface": est.surface,
             "particles": est.particles, "bonds": est.bonds, "contacts": est.contacts, "dofs": est.dofs,
             "first_neighbour": est.first_neighbour, "layered": bool(layered), "precision": str(est.d.dtype),
             "size_class": [est.n, est.n_bonds, est.n_contacts], "setup_time": setup_time}
    for name in ("k_bottom", "k_top", "n_bottom", "n_top"):
        if name in parts:
            stats[name] = float(parts[name]) if name.startswith("k") else int(parts[name])
    k = float(k)
    wall = time.perf_counter() - t0
    # what is neither setup nor compilation (moving the outputs to the host) counts as run time
    return settle(Result(method="ste", stiffness=k, youngs_modulus=k * length / area, gauge_length=length,
                         area=area, displacement=np.array([0.0, delta]), force=np.array([0.0, k * delta]),
                         wall_time=wall, setup_time=setup_time, compile_time=compile_time,
                         run_time=wall - setup_time - compile_time, stats=stats, state=None), throw)


def _check_params(params, sample: Sample):
    if not isinstance(params, dict) or not {"bond_E", "bond_nu"} <= set(params):
        raise SceneError("params must be a dict with 'bond_E' and 'bond_nu' (see jaxbpm.physics.model."
                         f"default_params), got {type(params).__name__}")
    m = sample.n_materials
    for name in ("bond_E", "bond_nu"):
        shape = np.shape(params[name])
        if shape != (m,):
            raise SceneError(f"params[{name!r}] must have shape [{m}] (one per bond material), got {shape}")
    E = np.asarray(params["bond_E"])
    if not np.all(np.isfinite(E) & (E > 0)):
        raise SceneError(f"params['bond_E'] must be finite and > 0, got {E.tolist()}")


# ---------------------------------------------------------------------------------------------------- local map
class LocalMap(NamedTuple):
    """The local stiffness map (Jarolin & Dosta 2020, 4.4): per particle, moduli averaged over a neighbourhood.

    positions ``[n, 3]`` [m]; E ``[n, 3]``: Young's moduli along x, y, z of the V-weighted mean tensor of the
    non-singular particles within ``radius`` of each particle [Pa] (NaN where there is none); deviation ``[n, 3]``:
    Eq. 36, ``(mean(E) - E) / mean(E)`` per direction; valid ``[n]``: particle not singular; radius [m].
    """

    positions: np.ndarray
    E: np.ndarray
    deviation: np.ndarray
    valid: np.ndarray
    radius: float


def local_map(sample: Sample, params=None, *, scene=None, radius: float | None = None, **options) -> LocalMap:
    """Local moduli averaged over spheres of ``radius`` (default 1.5 mean particle diameters, i.e. neighbourhoods
    three diameters across, as in Jarolin & Dosta 2020) and their deviation from the mean (Eq. 36)."""
    from scipy.sparse import coo_matrix, identity
    from scipy.spatial import cKDTree

    params = default_params(sample) if params is None else params
    _check_params(params, sample)
    est = estimator(sample, scene, pad=True, **options)
    c = np.asarray(_local_tensors_jit(est, params))[:sample.n_particles]
    rad = np.asarray(sample.radii)
    radius = 3.0 * float(np.mean(rad)) if radius is None else float(radius)
    if not (radius > 0 and np.isfinite(radius)):
        raise SceneError(f"radius must be a positive length, got {radius!r}")
    pos = np.asarray(sample.positions)
    n = sample.n_particles
    pairs = cKDTree(pos).query_pairs(radius, output_type="ndarray")
    adj = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    adj = (adj + adj.T + identity(n)).tocsr()
    valid = np.asarray(est.valid)[:n]
    w = np.where(valid, np.asarray(est.volume)[:n], 0.0)
    cw = np.where(valid[:, None, None], c, 0.0) * w[:, None, None]  # the map shows the surface too
    wsum = adj @ w
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (adj @ cw.reshape(n, 36)).reshape(n, 6, 6) / wsum[:, None, None]
        ok = wsum > 0
        e = np.full((n, 3), np.nan)
        e[ok] = 1.0 / np.diagonal(np.linalg.inv(mean[ok]), axis1=1, axis2=2)[:, :3]
        avg = np.nanmean(e, axis=0)
        deviation = (avg - e) / avg
    return LocalMap(positions=pos, E=e, deviation=deviation, valid=valid, radius=radius)


_MOVED = {"save_local_map", "export_local_map_vtk", "plot_local_map"}


def __getattr__(name):
    # the local map's writers live on the I/O side since 0.2 (jaxbpm.io); the old names work for one more release
    if name in _MOVED:
        import warnings

        from jaxbpm import io

        warnings.warn(f"jaxbpm.ste.{name} moved to jaxbpm.io.{name}; the old name goes in the next release",
                      DeprecationWarning, stacklevel=2)
        return getattr(io, name)
    raise AttributeError(f"module 'jaxbpm.ste' has no attribute {name!r}")
