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
* **Boundary forms** (``boundary``). ``"clamped"`` (the default): the particles the scene clamps (its end layers or
  ``fixed``/``driven`` masks) follow the affine field (``phi = 0``), as their prescribed displacements do in the
  DEM and the DSM; they bound the sample along the load and are left out of the averages (exact on a clamped
  simple-cubic lattice, where the affine field is the solution). ``"free"``: the paper's form, every particle
  relaxes, the clamped ones as one-sided surface particles. Walls clamp no particle: a scene with walls gets the
  free form.
* **Surface particles.** A particle whose centre lies within ``surface_depth`` (default one mean particle
  diameter) of the sample's free surface (its domain box or cylinder, else the spheres' bounding box; in the clamped
  form the faces parallel to the load only) has a one-sided neighbourhood: Eq. 32 lets it relax as if the missing
  neighbours were absent, which under-counts the stiffness of the bulk. Such particles keep their local tensor and
  their Gamma (they still act on their neighbours) but are left out of the averages; ``surface_depth=0`` averages
  over every particle that is not clamped, as the paper did for samples of 10^5 particles (in the free form).
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

The package: :mod:`~jaxbpm.ste.estimator` (what is built once per sample), :mod:`~jaxbpm.ste.tensor` (the tensors
and moduli), :mod:`~jaxbpm.ste.scene` (a scene's stiffness, :func:`solve_scene`, :func:`stiffness_function`) and
:mod:`~jaxbpm.ste.localmap` (the local stiffness map).
"""

from jaxbpm.ste.estimator import Estimator, estimator
from jaxbpm.ste.localmap import LocalMap, local_map
from jaxbpm.ste.scene import (
    SceneGeometry, layer_stiffness, scene_geometry, scene_stiffness, solve_scene, stiffness_function, wall_series)
from jaxbpm.ste.tensor import (
    VOIGT, body_tensor, directional_modulus, isotropic_fit, local_tensors, moduli, pair_stiffness, raw_body_tensor,
    tensor_from_voigt, voigt)

__all__ = [
    "Estimator", "estimator", "pair_stiffness", "local_tensors", "body_tensor", "raw_body_tensor", "voigt",
    "tensor_from_voigt", "moduli", "directional_modulus", "isotropic_fit", "layer_stiffness", "wall_series",
    "SceneGeometry", "scene_geometry", "scene_stiffness", "stiffness_function", "solve_scene", "LocalMap", "local_map",
    "VOIGT",
]
