"""The DEM's critical time step: the highest natural frequency of the bonded network (power iteration on
``M^-1/2 K M^-1/2``, K from the Jacobians of the same bond law at rest), plus contact and wall stiffness at a
reference overlap; ``dt_crit = 2 / omega_max``."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._compile import setup_jit
from jaxbpm.errors import InstabilityError
from jaxbpm.physics.model import Model

__all__ = ["critical_time_step"]


def critical_time_step(model: Model, params, *, contact_overlap: float = 0.01, iterations: int = 60) -> float:
    """Critical time step 2 / omega_max of the linearised model at rest [s].

    omega_max^2 of the bonds is found by power iteration on ``M^-1/2 K M^-1/2`` (K v from the Jacobians of the bond
    law at rest, translations and rotations, 81 numbers per bond; one jitted program), from a start whose row for a
    particle depends on its place in the sample alone (see ``_start_vector``), with a Rayleigh quotient summed
    exactly on the host: particles that no bond with stiffness joins (e.g. the padding of a size class) leave the
    estimate unchanged to the last bit, and a reordered, translated or scaled copy of the sample gets the same time
    step (scaled) to round-off.
    Contacts and walls add ``z k_c / m`` with the Hertz (or cohesive-law) stiffness at an overlap of
    ``contact_overlap`` times the smallest radius (z = 12 neighbours, 1 wall); the linear law's stiffness is
    constant: its larger of k_n and the shear spring with the rotation's lever (``_linear_omega2``). Discs count
    twelve too, not their six neighbours: the stiffest mode of a hexagonal packing of equal discs is ``8 max(k_n,
    3 k_s) / m`` (all discs turning at once against their shear springs), up to ``9 max(k_n, k_s) / m`` without
    rotations.

    Args:
        model: the run's model.
        params: the bond and contact parameters.
        contact_overlap: the reference overlap of contacts and walls, relative to the smallest radius.
        iterations: power iterations.

    Returns:
        The critical time step [s].

    Raises:
        InstabilityError: the model has no stiffness (no bonds, contacts or walls).
    """
    omega2 = 0.0
    if model.bonds.shape[0]:
        v0 = jax.device_put(_start_vector(model))
        power = _disc_omega2 if model.dim == 2 else _bond_omega2
        v, kv = power(model, params, v0, iterations=iterations)
        v, kv = np.asarray(v, np.float64).ravel(), np.asarray(kv, np.float64).ravel()
        # the Rayleigh quotient, exactly rounded sums: the same whatever zeros (padding) the vectors hold; it
        # approaches omega_max^2 from below: a 2 % margin
        omega2 = 1.02 * math.fsum(v * kv) / math.fsum(v * v) if np.all(np.isfinite(v)) else 0.0  # (no stiffness)
    r_min = float(np.min(np.asarray(model.radii)))
    m_min = float(np.min(np.asarray(model.mass)))
    delta = contact_overlap * r_min
    if model.contacts and model.contact_law == "cohesive":
        # linear spring-dashpot: k_N at the reference overlap; the dashpot lowers the stable step of an explicit
        # scheme by sqrt(1 + gamma^2) - gamma
        from jaxbpm.physics import cohesive as cohesive_mod

        c = model.cohesive
        k_c = float(cohesive_mod.normal_stiffness(r_min, r_min, delta, float(c.E)))
        gamma = float(cohesive_mod.restitution_damping(float(c.restitution)))
        omega2 += 12 * k_c / m_min / (np.sqrt(1.0 + gamma**2) - gamma) ** 2
    elif model.contacts and model.contact_law == "linear":
        omega2 += 12 * _linear_omega2(model, params, r_min) / m_min
    elif model.contacts:
        k_c = 2.0 * float(model.contact.E_star) * np.sqrt(0.5 * r_min * delta)
        omega2 += 12 * k_c / m_min
    if model.walls == "hertz":
        omega2 += 2.0 * float(model.wall_stiffness) * np.sqrt(r_min * delta) / m_min
    elif model.walls == "linear":
        omega2 += float(model.wall_stiffness) / m_min
    if omega2 <= 0:
        raise InstabilityError("cannot estimate a time step: the model has no stiffness (no bonds, contacts or walls)")
    return 2.0 / np.sqrt(omega2)


def _linear_omega2(model: Model, params, r_min: float) -> float:
    """``k m / m`` of the stiffest mode of one linear contact on a particle of the smallest radius and mass ``m``: the
    normal spring ``k_n = E* A / L`` (largest between two of the smallest particles: ``pi E* r_min / 2`` in 3D,
    ``E* t`` for discs of thickness t), or the shear spring ``k_s = k_n / kratio`` on the contact point, which moves
    with the particle's translation and rotation (``1 / m + r^2 / I = 3.5 / m`` for a solid sphere, ``3 / m`` for a
    disc, ``1 / m`` without rotations); the dashpots lower the stable step of an explicit scheme by
    ``sqrt(1 + beta^2) - beta``."""
    from jaxbpm.physics.linear import normal_stiffness

    p = model.hertz_params(params)
    kn = float(normal_stiffness(r_min, r_min, float(p.emod), model.dim, float(p.thickness)))
    lever = (3.5 if model.dim == 3 else 3.0) if model.rotations else 1.0
    k = max(kn, lever * kn / float(p.kratio))
    if p.beta is not None:
        beta = float(p.beta)
        k /= (np.sqrt(1.0 + beta**2) - beta) ** 2
    return k


#: wave vectors (per largest radius) and phases of the power iteration's start, one row per DOF: lengths about 2.5
#: (a wavelength of about a particle diameter) in directions and with phases that share no simple ratio
_WAVES = np.array([[2.13, 1.37, 0.71], [-0.83, 2.29, 1.19], [1.57, -0.67, 2.03],
                   [0.97, 1.83, -1.61], [-2.11, 0.59, 1.43], [1.21, -1.97, -0.89]])
_PHASES = np.array([0.31, 1.73, 2.47, 0.89, 3.11, 2.03])


def _start_vector(model: Model) -> np.ndarray:
    """``[n, 6]`` the start of the power iteration, made on the host: for each particle a smooth function (sines of
    its position, relative to the lowest corner of the bonded particles, over their largest radius), so that the
    estimate depends neither on the order of the particles nor on where the sample lies or how large it is (a
    reordered, translated or scaled copy gets the same time step to round-off), nor on padding (particles without a
    bond of some cross-section set neither the corner nor the radius)."""
    pos = np.asarray(model.positions0, np.float64)
    live = np.asarray(model.bond_area) > 0
    bonded = np.zeros(pos.shape[0], bool)
    bonded[np.asarray(model.bonds)[live].ravel()] = True
    if not bonded.any():
        bonded[:] = True
    p = (pos - pos[bonded].min(axis=0)) / float(np.max(np.asarray(model.radii)[bonded]))
    if model.dim == 2:  # discs: (u_x, u_y[, theta])
        nd = model.dofs
        return np.sin(p @ _WAVES[:nd, :2].T + _PHASES[:nd]).astype(model.positions0.dtype)
    return np.sin(p @ _WAVES.T + _PHASES).astype(model.positions0.dtype)


@setup_jit(static_argnames=("iterations",))
def _bond_omega2(model: Model, params, v0, iterations):
    """The last iterate ``v`` of the power iteration on ``M^-1/2 K M^-1/2`` and ``M^-1/2 K M^-1/2 v``, ``[n, 6]``."""
    from jaxbpm.physics.bond import bond_law

    n, dtype = model.n, model.positions0.dtype
    k = model.stiffness(params)

    def jacobian(r0, kn, kt, ktw, kb):
        # one bond at rest: (f_i, m_i, m_j) against (d = x_j - x_i, the rotation vectors of i and j); a rotation
        # vector w turns the identity by the quaternion (1, w / 2) to first order
        def law(z):
            one = jnp.ones(1, dtype)
            q_i, q_j = jnp.concatenate([one, 0.5 * z[3:6]]), jnp.concatenate([one, 0.5 * z[6:]])
            out = bond_law(r0 + z[:3], r0, q_i, q_j, kn, kt, ktw, kb)
            return jnp.concatenate([out.f_i, out.m_i, out.m_j])

        return jax.jacfwd(law)(jnp.zeros(9, dtype))

    # the Jacobians once ([nb, 9, 9]: the same bond law, linearised), then each iteration is a gather, a small
    # product and a scatter (a Jacobian-vector product of the whole force function costs ten DEM steps on CPU)
    jac = jax.vmap(jacobian)(model.r0, k.kn, k.kt, k.ktw, k.kb)
    if not model.rotations:
        jac = jac[:, :3, :3]
    i, j = model.bonds[:, 0], model.bonds[:, 1]
    scale = jnp.concatenate([jnp.broadcast_to(model.mass[:, None], (n, 3)),
                             jnp.broadcast_to(model.inertia[:, None], (n, 3))], axis=1) ** -0.5

    def apply(v):
        u = scale * v
        u_i, u_j = u[i], u[j]
        if model.rotations:
            z = jnp.concatenate([u_j[:, :3] - u_i[:, :3], u_i[:, 3:], u_j[:, 3:]], axis=1)
            out = jnp.einsum("bkl,bl->bk", jac, z)
            rows = jnp.concatenate([out[:, :6], jnp.concatenate([-out[:, :3], out[:, 6:]], axis=1)])
        else:
            f = jnp.einsum("bkl,bl->bk", jac, u_j[:, :3] - u_i[:, :3])
            rows = jnp.concatenate([jnp.concatenate([f, jnp.zeros_like(f)], axis=1),
                                    jnp.concatenate([-f, jnp.zeros_like(f)], axis=1)])
        return -scale * jax.ops.segment_sum(rows, jnp.concatenate([i, j]), n)

    # particles without bond stiffness (loose ones, padding) start at rest: K is zero there, and leaving them out of
    # the start makes every iterate, normalised by its largest entry (a maximum, in any order), the same to the bit
    # with or without padding
    per_bond = k.kn + k.kt + k.ktw + k.kb
    stiff = jax.ops.segment_sum(jnp.concatenate([per_bond, per_bond]), jnp.concatenate([i, j]), n) > 0
    v0 = jnp.where(stiff[:, None], v0, 0.0)
    if not model.rotations:
        v0 = v0.at[:, 3:].set(0.0)

    def body(v, _):
        w = apply(v)
        return w / jnp.max(jnp.abs(w)), None

    v, _ = jax.lax.scan(body, v0 / jnp.max(jnp.abs(v0)), None, length=iterations)
    return v, apply(v)


@setup_jit(static_argnames=("iterations",))
def _disc_omega2(model: Model, params, v0, iterations):
    """:func:`_bond_omega2` of a two-dimensional model: ``[n, dofs]`` iterates, ``K`` from the pair stiffness of the
    2D bond law (:func:`jaxbpm.physics.tangent.bond_full`)."""
    from jaxbpm.physics import tangent

    n, nd = model.n, model.dofs
    k = model.stiffness(params)
    pair = tangent.bond_full(model.r0, k, model.rotations)  # [nb, 2 nd, 2 nd], stiffness
    i, j = model.bonds[:, 0], model.bonds[:, 1]
    scale = jnp.concatenate([jnp.broadcast_to(model.mass[:, None], (n, 2)), model.inertia[:, None]],
                            axis=1)[:, :nd] ** -0.5

    def apply(v):
        u = scale * v
        y = jnp.einsum("bkl,bl->bk", pair, jnp.concatenate([u[i], u[j]], axis=1))
        return scale * jax.ops.segment_sum(jnp.concatenate([y[:, :nd], y[:, nd:]]), jnp.concatenate([i, j]), n)

    per_bond = k.kn + k.kt + k.kb
    stiff = jax.ops.segment_sum(jnp.concatenate([per_bond, per_bond]), jnp.concatenate([i, j]), n) > 0
    v0 = jnp.where(stiff[:, None], v0, 0.0)

    def body(v, _):
        w = apply(v)
        return w / jnp.max(jnp.abs(w)), None

    v, _ = jax.lax.scan(body, v0 / jnp.max(jnp.abs(v0)), None, length=iterations)
    return v, apply(v)
