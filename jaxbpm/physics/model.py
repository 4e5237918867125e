"""The Model: the interactions a scene needs, and one force function that every solver calls.

A :class:`Model` holds the sample's arrays in JAX form and a few static switches:

* ``rotations``: particles carry orientations (6 DOF each) or not (3 DOF: bonds then act on relative translation
  only, as in the 3N direct stiffness method of Jarolin & Dosta 2020). Default: on whenever the sample has bonds (they
  transmit bending and twisting moments) or contacts with friction. A two-dimensional sample's discs have 3 DOF
  (u_x, u_y, theta) with rotations and 2 without; their bonds follow :mod:`jaxbpm.physics.bond2d`.
* ``contacts``: particle contacts (with a neighbour list in the DEM) or none; ``contact_law``: ``"hertz"``
  (Hertz-Mindlin, :mod:`jaxbpm.physics.contact`, the default), ``"linear"`` (PFC's linear contact model,
  :mod:`jaxbpm.physics.linear`, whose scalars live in ``contact``) or ``"cohesive"`` (the stress-dependent cohesive
  law of Irazabal et al. 2023, :mod:`jaxbpm.physics.cohesive`, whose scalars live in ``cohesive``).
* ``walls``: the wall law (``"hertz"``/``"linear"``) or ``None``.

Parameters that calibrators change live in a small pytree ``params = {"bond_E": [n_materials],
"bond_nu": [n_materials]}``, mapped onto bonds by the material index, so ``grad``/``vmap``/optax all see one thing
(:mod:`jaxbpm.physics.params`).
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm.physics import bond as bond_mod
from jaxbpm.physics import cohesive as cohesive_mod
from jaxbpm.physics import contact as contact_mod
from jaxbpm.physics import linear as linear_mod
from jaxbpm.physics import wall as wall_mod
from jaxbpm.physics.params import _float_dtype, _put, check_params, default_params  # noqa: F401
from jaxbpm.sample import Sample

__all__ = ["Model", "build_model", "contact_params"]

#: on the CPU the DEM's bond pass runs over blocks of BOND_BLOCK bonds on models of at least BLOCKED_FROM bonds
#: (:func:`jaxbpm.physics.bond.bond_forces_breaking`: a block's intermediates of the law stay in the caches, where
#: one pass over all bonds keeps them in memory); below, and on accelerators (where a loop of blocks would run its
#: kernels one block after another), in one pass (``Model.bond_block``)
BOND_BLOCK, BLOCKED_FROM = 4096, 65536


@dataclasses.dataclass(frozen=True)
class Model:
    """Arrays of the sample in JAX form plus static switches (a pytree). Build it with :func:`build_model`.

    Attributes:
        positions0: ``[n, 3]`` reference positions [m] (``[n, 2]``: discs).
        radii: ``[n]`` [m].
        mass: ``[n]`` [kg].
        inertia: ``[n]`` moments of inertia [kg m^2].
        bonds: ``[nb, 2]`` particle indices.
        r0: ``[nb, 3]`` reference bond vectors [m] (``[nb, 2]``: discs).
        bond_material: ``[nb]`` material index of each bond.
        bond_area: ``[nb]`` cross-sections [m^2].
        bond_I: ``[nb]`` second moments of area [m^4].
        bond_J: ``[nb]`` polar moments of area [m^4].
        bond_length: ``[nb]`` initial lengths [m].
        bond_keys: ``[nb]`` sorted keys ``i * n + j`` of the bonded pairs (to exclude them from contacts).
        bond_key_index: ``[nb]`` bond index of each sorted key.
        bond_radius: ``[nb]`` r_b [m].
        bond_tensile: ``[n_materials]`` tensile strength sigma_c [Pa] (inf: unbreakable).
        bond_cohesion: ``[n_materials]`` shear strength (cohesion) c [Pa].
        contact: the Hertz-Mindlin parameters, or with ``contact_law="linear"`` the linear law's
            :class:`~jaxbpm.physics.linear.LinearParams`.
        wall_stiffness: E* of a particle on a rigid wall [Pa] (``"hertz"``) or k [N/m] (``"linear"``).
        rotations: 6 DOF per particle (else 3).
        contacts: particle contacts on.
        walls: the wall law, ``"hertz"``, ``"linear"`` or ``None``.
        bond_contact: how contacts of bonded pairs combine with the bond (``"superimpose"``).
        breakage: bonds break.
        cohesive: the cohesive law's :class:`~jaxbpm.physics.cohesive.CohesiveParams` with
            ``contact_law="cohesive"``.
        failure_rule: how a bond's stresses break it (:data:`jaxbpm.physics.bond.FAILURE_RULES`).
        contact_law: ``"hertz"``, ``"linear"`` or ``"cohesive"``.
        bond_block: the DEM's bond pass in blocks of this many bonds (``None``: one pass).
    """

    positions0: Any
    radii: Any
    mass: Any
    inertia: Any
    bonds: Any
    r0: Any
    bond_material: Any
    bond_area: Any
    bond_I: Any
    bond_J: Any
    bond_length: Any
    bond_keys: Any
    bond_key_index: Any
    bond_radius: Any
    bond_tensile: Any
    bond_cohesion: Any
    contact: contact_mod.ContactParams
    wall_stiffness: Any
    rotations: bool = True
    contacts: bool = False
    walls: str | None = None
    bond_contact: str = "superimpose"
    breakage: bool = False
    cohesive: Any = None
    failure_rule: str = "separate"
    contact_law: str = "hertz"
    bond_block: int | None = None

    @property
    def n(self) -> int:
        """The number of particles."""
        return int(self.positions0.shape[0])

    @property
    def dim(self) -> int:
        """The spatial dimension of the positions (``[n, dim]``), the sample's."""
        return int(self.positions0.shape[1])

    @property
    def dofs(self) -> int:
        """Degrees of freedom per particle: ``dim`` translations, and with :attr:`rotations` the rotations the
        dimension has (three in 3D)."""
        return self.dim + (self.dim * (self.dim - 1) // 2 if self.rotations else 0)

    def stiffness(self, params) -> bond_mod.BondStiffness:
        """Per-bond stiffnesses from the parameters.

        Args:
            params: the parameter dict (or :meth:`precompute`'s), or a
                :class:`~jaxbpm.physics.bond.BondStiffness`, which passes through unchanged (so that loops can
                compute it once).

        Returns:
            The bonds' stiffnesses (``[nb]`` arrays).
        """
        if isinstance(params, bond_mod.BondStiffness):
            return params
        if "_stiffness" in params:  # precomputed (see :meth:`precompute`)
            return params["_stiffness"]
        E = jnp.asarray(params["bond_E"])[self.bond_material]
        nu = jnp.asarray(params["bond_nu"])[self.bond_material]
        return bond_mod.stiffness(E, nu, self.bond_area, self.bond_I, self.bond_J, self.bond_length)

    def strength(self, params) -> bond_mod.BondStrength | None:
        """Per-bond strengths.

        Args:
            params: the parameter dict; it may override the material table with ``"bond_tensile_strength"``,
                ``"bond_shear_strength"`` (cohesion c) [Pa] and ``"bond_friction_angle"`` phi [rad] of the
                Mohr-Coulomb shear strength (default 0: constant) and ``"bond_moment_factor"`` beta in [0, 1], the
                share of the bending and twisting moments in the rim stresses (PFC's ``pb_mcf``; default 1: the full
                moments).

        Returns:
            The bonds' :class:`~jaxbpm.physics.bond.BondStrength`, or ``None`` when the model does not break bonds.
        """
        if not self.breakage:
            return None
        if isinstance(params, dict) and "_strength" in params:
            return params["_strength"]
        get = params.get if isinstance(params, dict) else (lambda key, default=None: default)
        mat = self.bond_material
        tensile = jnp.asarray(get("bond_tensile_strength", self.bond_tensile))[mat]
        cohesion = jnp.asarray(get("bond_shear_strength", self.bond_cohesion))[mat]
        phi = get("bond_friction_angle", None)
        tan_phi = jnp.zeros_like(cohesion) if phi is None else jnp.tan(jnp.asarray(phi))[mat]
        beta = get("bond_moment_factor", None)
        beta = jnp.ones_like(cohesion) if beta is None else jnp.asarray(beta, cohesion.dtype)[mat]
        # a bond without cross-section (the padding of a size class) carries nothing and never breaks: infinite
        # strengths, and a unit section so that its (zero) stresses are not 0 / 0
        solid = self.bond_area > 0
        area, inertia, polar = (jnp.where(solid, a, 1.0) for a in (self.bond_area, self.bond_I, self.bond_J))
        return bond_mod.BondStrength(tensile=jnp.where(solid, tensile, jnp.inf),
                                     cohesion=jnp.where(solid, cohesion, jnp.inf), tan_phi=tan_phi,
                                     radius=self.bond_radius, area=area, inertia=inertia, polar=polar,
                                     moment_factor=beta)

    #: params keys that override the cohesive law's scalars (see :meth:`cohesive_params`)
    COHESIVE_KEYS = {"contact_E": "E", "contact_nu": "nu", "friction": "friction", "restitution": "restitution",
                     "cohesion_initial": "c0", "cohesion_from_stress": "kc", "cohesion_max": "c_max"}

    def cohesive_params(self, params) -> cohesive_mod.CohesiveParams | None:
        """The cohesive law's scalars.

        Args:
            params: the parameter dict; it may override them with ``"contact_E"``, ``"contact_nu"``,
                ``"friction"``, ``"restitution"``, ``"cohesion_initial"`` (c_0), ``"cohesion_from_stress"`` (k_c)
                and ``"cohesion_max"`` (c_max), scalars.

        Returns:
            The :class:`~jaxbpm.physics.cohesive.CohesiveParams`, or ``None`` with Hertz contacts.
        """
        if self.contact_law != "cohesive":
            return None
        if not isinstance(params, dict):
            return self.cohesive
        if "_cohesive" in params:
            return params["_cohesive"]
        over = {field: jnp.asarray(params[key]) for key, field in self.COHESIVE_KEYS.items() if key in params}
        return self.cohesive._replace(**over) if over else self.cohesive

    #: params keys that override the linear law's scalars (see :meth:`hertz_params`)
    LINEAR_KEYS = {"contact_emod": "emod", "contact_kratio": "kratio", "friction": "friction"}

    def hertz_params(self, params):
        """The parameters of the contact law the pair functions of :mod:`jaxbpm.physics.contact` run: Hertz-Mindlin's,
        or with ``contact_law="linear"`` the linear law's.

        Args:
            params: the parameter dict; ``"contact_E"`` and ``"contact_nu"`` (scalars, differentiable) replace the
                particles' contact modulus and Poisson's ratio where given (Hertz-Mindlin); ``"contact_emod"``,
                ``"contact_kratio"`` and ``"friction"`` replace E*, k_n / k_s and mu (the linear law).

        Returns:
            The :class:`~jaxbpm.physics.contact.ContactParams` or :class:`~jaxbpm.physics.linear.LinearParams`.
        """
        c = self.contact
        if isinstance(params, dict) and "_contact" in params:
            return params["_contact"]
        if self.contact_law == "linear":
            if not isinstance(params, dict):
                return c
            over = {field: jnp.asarray(params[key], c.emod.dtype) for key, field in self.LINEAR_KEYS.items()
                    if key in params}
            return c._replace(**over) if over else c
        if not isinstance(params, dict) or not ({"contact_E", "contact_nu"} & set(params)):
            return c
        r = c.G_star / c.E_star  # = (1 - nu) / (2 (2 - nu)) for one material: recover the sample's E and nu
        nu0 = (1.0 - 4.0 * r) / (1.0 - 2.0 * r)
        e0 = 2.0 * c.E_star * (1.0 - nu0 ** 2)
        e = jnp.asarray(params.get("contact_E", e0), c.E_star.dtype)
        nu = jnp.asarray(params.get("contact_nu", nu0), c.E_star.dtype)
        g = e / (2.0 * (1.0 + nu))
        return c._replace(E_star=e / (2.0 * (1.0 - nu ** 2)), G_star=g / (2.0 * (2.0 - nu)))

    def precompute(self, params) -> dict:
        """Per-bond stiffnesses and strengths (and the contact laws' scalars, and with Hertz or linear contacts the
        bonded pairs' radii) computed once.

        Args:
            params: the parameter dict.

        Returns:
            A dict that a loop of force evaluations passes instead of ``params``.
        """
        out = {"_stiffness": self.stiffness(params), "_strength": self.strength(params),
               "_contact": self.hertz_params(params)}
        if self.contact_law == "cohesive":
            out["_cohesive"] = self.cohesive_params(params)
        elif self.contacts:
            out["_bond_radii"] = self.radii[self.bonds.T]  # [2, nb]: the bonded pairs' radii, read in order
        return out

    def bonded(self, pairs, intact=None):
        """Whether each candidate pair is bonded.

        Args:
            pairs: ``[C, 2]`` candidate pairs, i < j.
            intact: ``[nb]`` bool, or ``None``: every bond counts.

        Returns:
            ``[C]`` bool: bonded (by an intact bond, when ``intact`` is given).
        """
        if self.bond_keys.shape[0] == 0:
            return jnp.zeros(pairs.shape[0], bool)
        key_t = self.bond_keys.dtype
        key = pairs[:, 0].astype(key_t) * self.n + pairs[:, 1].astype(key_t)
        pos = jnp.clip(jnp.searchsorted(self.bond_keys, key), 0, self.bond_keys.shape[0] - 1)
        found = self.bond_keys[pos] == key
        if intact is not None:
            found = found & intact[self.bond_key_index[pos]]
        return found

    def forces(self, positions, orientations, params, intact=None, contacts=None, wall_points=None,
               wall_normals=None, bond_contacts=None, block=None):
        """Forces and moments on every particle, and the parts they came from.

        Args:
            positions: ``[n, 3]`` particle positions [m] (``[n, 2]``: discs).
            orientations: ``[n, 4]`` unit quaternions (discs: ``[n, 1]`` rotation angles [rad]; ignored without
                rotations).
            params: the parameter dict (or :meth:`precompute`'s).
            intact: ``[nb]`` bool, or ``None``: all bonds intact.
            contacts: ``None`` or a tuple ``(pairs [C, 2], valid [C], spring [C, 3], dxi [C, 3], v_rel [C, 3])``;
                the cohesive law takes a sixth entry, the cohesion history ``[C]`` (zeros, i.e. new contacts, when
                absent).
            wall_points: ``[W, 3]`` when the model has walls.
            wall_normals: ``[W, 3]`` when the model has walls.
            bond_contacts: ``None`` or ``(spring [nb, 3], motion, valid [nb])``: the Hertz-Mindlin law also on the
                bonded pairs (``valid``: where it applies), evaluated in the bond law's pass over the bonds (their
                rows scattered to the particles after the bond law's; the DEM's contacts of bonded pairs);
                ``motion(i, j, d, r_i, r_j)`` gives the pairs' ``(dxi, v_rel)`` from their particle indices, vectors
                ``d = x_j - x_i`` (component tuples) and radii; ``contacts`` then hold the other pairs.
            block: pass over the bonds in blocks of this many (see :func:`jaxbpm.physics.bond.bond_forces_breaking`;
                ``parts["bonds"]`` is then ``None``).

        Returns:
            ``(force, moment, parts)``: ``[n, 3]`` [N], ``[n, 3]`` [N m] and ``parts = {"bonds": BondForces,
            "contacts": ContactForces or None, "walls": [W, 3] reactions or None, "intact": the new intact mask
            (bonds that broke in this evaluation removed; the given one without breakage), "broken": break mode of
            each bond in this evaluation (0: none, 1: tensile, 2: shear; None without breakage), "bond_contacts": the
            bonded pairs' new springs [nb, 3] or None}``.
        """
        k = self.stiffness(params)
        extra = None if bond_contacts is None else self._bond_contact_law(params, *bond_contacts)
        force, moment, bf, intact, broken, *more = bond_mod.bond_forces_breaking(
            positions, orientations if self.rotations else None, self.bonds, self.r0, k, intact,
            self.strength(params), self.failure_rule, extra, block)
        parts = {"bonds": bf, "contacts": None, "walls": None, "intact": intact, "broken": broken,
                 "bond_contacts": jnp.stack(more[0], axis=-1) if more else None}
        if self.contacts and contacts is not None and self.contact_law == "cohesive":
            pairs, valid, spring, dxi, v_rel = contacts[:5]
            history = contacts[5] if len(contacts) > 5 else jnp.zeros(pairs.shape[0], positions.dtype)
            fc, mc, cf = cohesive_mod.pair_forces(positions, pairs, valid, self.radii, self.mass, spring, dxi, v_rel,
                                                  history, self.cohesive_params(params))
            force, moment = force + fc, moment + mc
            parts["contacts"] = cf
        elif self.contacts and contacts is not None:
            pairs, valid, spring, dxi, v_rel = contacts
            fc, mc, cf = contact_mod.pair_forces(positions, pairs, valid, self.radii, self.mass, spring, dxi, v_rel,
                                                 self.hertz_params(params))
            force, moment = force + fc, moment + mc
            parts["contacts"] = cf
        if self.walls is not None:
            fw, reaction = wall_mod.wall_forces(positions, self.radii, wall_points, wall_normals, self.walls,
                                                self.wall_stiffness)
            force = force + fw
            parts["walls"] = reaction
        return force, moment, parts

    def _bond_contact_law(self, params, spring, motion, valid):
        """The ``extra`` of :func:`jaxbpm.physics.bond.bond_forces_breaking`: the Hertz-Mindlin law on the bonded
        pairs (their new springs as aux)."""
        p = self.hertz_params(params)
        radii = params.get("_bond_radii") if isinstance(params, dict) else None

        def law(i, j, d, take):
            r_i, r_j = (self.radii[i], self.radii[j]) if radii is None else (take(radii[0]), take(radii[1]))
            dxi, v_rel = motion(i, j, d, r_i, r_j)
            cf = contact_mod.law_components(d, r_i, r_j, self.mass[i], self.mass[j],
                                            contact_mod._components(take(spring)), dxi, v_rel, p, take(valid))
            return cf.f_i, cf.m_i, cf.m_j, cf.spring

        return law


jax.tree_util.register_dataclass(
    Model,
    data_fields=["positions0", "radii", "mass", "inertia", "bonds", "r0", "bond_material", "bond_area", "bond_I",
                 "bond_J", "bond_length", "bond_keys", "bond_key_index", "bond_radius", "bond_tensile",
                 "bond_cohesion", "contact", "wall_stiffness", "cohesive"],
    meta_fields=["rotations", "contacts", "walls", "bond_contact", "breakage", "contact_law", "failure_rule",
                 "bond_block"],
)


def build_model(sample: Sample, *, contacts: bool = False, walls: str | None = None, rotations: bool | None = None,
                contact_damping: bool = False, wall_stiffness: float | None = None,
                breakage: bool = False, contact_law="hertz", cohesive=None, pad_to=None,
                failure_rule: str = "separate") -> Model:
    """A :class:`Model` of a sample with just the interactions asked for.

    The setup is NumPy on the host: building a model compiles no program (beyond one, once per process, for the
    contact parameters).

    Args:
        sample: the sample.
        contacts: particle contacts on.
        walls: ``None``, ``"hertz"`` (default wall stiffness: the particle material on a rigid plane,
            E / (1 - nu^2)) or ``"linear"`` (give ``wall_stiffness`` in N/m).
        rotations: ``None`` picks 6 DOF per particle when the sample has bonds or frictional contacts, else 3.
            Particles with cohesive contacts and no bonds do not rotate by default (Irazabal et al. 2023).
        contact_damping: Tsuji damping of the Hertz-Mindlin contacts (the dashpots of the linear law).
        wall_stiffness: the walls' stiffness (see :attr:`Model.wall_stiffness`), or ``None``: the default.
        breakage: bonds break when their stresses exceed the strengths of the material table (or of the params);
            off by default (the static solvers model the elastic range).
        contact_law: ``"hertz"`` (default), ``"linear"`` (PFC's linear contact model, its parameters from the
            particle material: :class:`~jaxbpm.physics.linear.LinearLaw`), a ``LinearLaw``, ``"cohesive"`` or a
            :class:`~jaxbpm.physics.cohesive.CohesiveLaw`.
        cohesive: the cohesive law's parameters (a ``CohesiveLaw`` or a mapping of its fields) with
            ``contact_law="cohesive"``.
        pad_to: ``(particles, bonds)`` capacities (a :class:`~jaxbpm._compile.SizeClass`) to pad a bonds-only
            model to, so that the samples of one size class share compiled programs. The sample's particles and
            bonds come first; the extra particles lie in a row beyond the sample, with the largest radius, mass and
            moment of inertia of the sample's particles (so its minima and maxima stay those of the sample); the
            extra bonds join pairs of distinct extra particles, with a zero cross-section (no stiffness, no force:
            ``r0`` is their actual distance) and unit length, and never break. A padded model's DEM loading clamps
            the extra particles at rest (:func:`jaxbpm.dem.pad_loading`) and its state holds the sample's first
            (:func:`jaxbpm.dem.unpad_state`). Not with contacts or walls (they would see the extra particles).
        failure_rule: how the stresses combine when bonds break (:data:`jaxbpm.physics.bond.FAILURE_RULES`):
            ``"separate"`` (default: tension and shear checked apart, the parallel bond), ``"summed"`` (LAMMPS
            ``bpm/rotational``) or ``"max"`` (Yade's ``CohFrictPhys``).

    Returns:
        The :class:`Model`.

    Raises:
        SceneError: an unknown contact law, cohesive parameters out of range, or walls or contacts other than the
            linear law's asked of a two-dimensional sample.
        ValueError: an unknown wall law or failure rule, ``walls="linear"`` without ``wall_stiffness``, padding with
            contacts or walls, or to capacities too small.
    """
    pm = sample.particle_material
    law = cohesive_mod.resolve_contact_law(contact_law, cohesive)
    linear = law if isinstance(law, linear_mod.LinearLaw) else None
    law = None if linear is not None else law
    if sample.dim == 2 and (walls is not None or (contacts and linear is None)):
        from jaxbpm.errors import SceneError

        raise SceneError("a two-dimensional sample's model has bonds and linear contacts (contact_law='linear') "
                         "only: walls and Hertz-Mindlin or cohesive contacts between discs are not available in 2D")
    thickness = float(sample.thickness) if sample.dim == 2 else 1.0
    if rotations is None:
        if law is not None:
            rotations = sample.n_bonds > 0
        else:
            mu = pm.friction if linear is None or linear.friction is None else linear.friction
            rotations = sample.n_bonds > 0 or (contacts and float(mu) > 0)
    if linear is not None and contacts:
        _warn_rest_overlaps(sample, linear.params(pm, thickness=thickness))
    dtype = _float_dtype()
    if dtype != np.float64:
        warnings.warn("jaxbpm: JAX is running in float32; bonded-particle stiffness solves lose precision. "
                      "Call jax.config.update('jax_enable_x64', True) first.", stacklevel=3)
    mats = sample.materials
    if walls == "hertz":
        ws = float(pm.E) / (1.0 - float(pm.nu) ** 2) if wall_stiffness is None else wall_stiffness
    elif walls == "linear":
        if wall_stiffness is None:
            raise ValueError("walls='linear' needs wall_stiffness [N/m]")
        ws = wall_stiffness
    elif walls is None:
        ws = 0.0
    else:
        raise ValueError(f"unknown wall law {walls!r}; use 'hertz', 'linear' or None")
    arrays = {"positions0": np.asarray(sample.positions, np.float64), "radii": np.asarray(sample.radii, np.float64),
              "mass": np.asarray(sample.mass, np.float64), "inertia": np.asarray(sample.inertia, np.float64),
              "bonds": np.asarray(sample.bonds, np.int64).reshape(-1, 2),
              "bond_material": np.asarray(sample.bond_material, np.int64),
              "bond_area": np.asarray(sample.bond_area, np.float64), "bond_I": np.asarray(sample.bond_I, np.float64),
              "bond_J": np.asarray(sample.bond_J, np.float64),
              "bond_length": np.asarray(sample.bond_length, np.float64),
              "bond_radius": np.asarray(sample.bond_radius, np.float64)}
    if pad_to is not None:
        if contacts or walls is not None:
            raise ValueError("pad_to pads bonds-only models: contacts and walls would see the extra particles")
        arrays = _padded(arrays, int(pad_to[0]), int(pad_to[1]))
    pos, bonds = arrays["positions0"], arrays["bonds"]
    n = pos.shape[0]
    all_keys = bonds[:, 0] * n + bonds[:, 1]
    key_index = np.argsort(all_keys, kind="stable")
    keys = all_keys[key_index]
    floats = {k: _put(v, dtype) for k, v in arrays.items() if v.dtype == np.float64}
    return Model(
        **floats,
        bonds=_put(bonds, np.int32),
        r0=_put(pos[bonds[:, 1]] - pos[bonds[:, 0]], dtype),
        bond_material=_put(arrays["bond_material"], np.int32),
        bond_keys=_put(keys, np.int64 if jax.config.jax_enable_x64 else np.int32),
        bond_key_index=_put(key_index, np.int32),
        bond_tensile=_put(mats.tensile_strength, dtype),
        bond_cohesion=_put(mats.shear_strength, dtype),
        contact=(contact_params(float(pm.E), float(pm.nu), float(pm.friction), float(pm.restitution), dtype.name,
                                bool(contact_damping)) if linear is None
                 else linear.params(pm, dtype, bool(contact_damping), thickness)),
        wall_stiffness=_put(ws, dtype),
        rotations=bool(rotations),
        contacts=bool(contacts),
        walls=walls,
        bond_contact=sample.bond_contact,
        breakage=bool(breakage) and sample.n_bonds > 0,
        failure_rule=bond_mod.check_failure_rule(failure_rule),
        cohesive=None if law is None else law.params(pm, dtype),
        contact_law="cohesive" if law is not None else "hertz" if linear is None else "linear",
        bond_block=BOND_BLOCK if bonds.shape[0] >= BLOCKED_FROM and jax.default_backend() == "cpu" else None,
    )


def _warn_rest_overlaps(sample: Sample, p) -> None:
    """Warn when bonded particles overlap at rest: PFC's linear law (absolute overlap) pushes them apart from the
    start with ``k_n delta``, large beside Hertz's ``delta^1.5`` force, and a generated sample is not balanced there."""
    if not sample.n_bonds:
        return
    b, rad = np.asarray(sample.bonds), np.asarray(sample.radii, np.float64)
    r_i, r_j = rad[b[:, 0]], rad[b[:, 1]]
    overlap = r_i + r_j - np.asarray(sample.bond_length, np.float64)
    rel = overlap / np.minimum(r_i, r_j)
    over = rel > 1e-9
    if over.any():
        kn = np.asarray(linear_mod.normal_stiffness(r_i, r_j, float(p.emod), sample.dim, float(p.thickness)))
        warnings.warn(f"linear contacts: {int(over.sum())} of {sample.n_bonds} bonded pairs overlap at rest (up to "
                      f"{float(rel.max()):.3g} of the smaller radius): the linear law (k_n delta) pushes them apart "
                      f"from the start, with up to {float(np.max(kn * np.maximum(overlap, 0.0))):.3g} N, which the "
                      "bonds hold and the particles' motion relaxes; for a sample at rest, shrink the radii below the "
                      "bond lengths (sample.replace(radii=...))", stacklevel=3)


def _padded(arrays: dict, n_cap: int, nb_cap: int) -> dict:
    """The NumPy arrays of :func:`build_model` padded to ``n_cap`` particles and ``nb_cap`` bonds (see its
    ``pad_to``)."""
    pos, n, nb = arrays["positions0"], arrays["positions0"].shape[0], arrays["bonds"].shape[0]
    if n_cap < n or nb_cap < nb or (nb_cap > nb and n_cap < n + 2):
        raise ValueError(f"cannot pad {n} particles and {nb} bonds to ({n_cap}, {nb_cap}): padding bonds need two "
                         "extra particles")
    r_max = float(arrays["radii"].max())
    row = np.arange(1, n_cap - n + 1, dtype=np.float64)[:, None] * (4.0 * r_max * np.eye(pos.shape[1])[0])
    extra_n, extra_b = n_cap - n, nb_cap - nb

    def grow(name, fill, count, shape=()):
        a = arrays[name]
        return np.concatenate([a, np.full((count, *shape), fill, a.dtype)])

    out = dict(arrays)
    out["positions0"] = np.concatenate([pos, pos.max(axis=0) + row])
    for name in ("radii", "mass", "inertia"):
        out[name] = grow(name, arrays[name].max(), extra_n)
    # spread over the extra particles (many bonds on one pair would make the scatter of forces slow)
    ring = np.arange(extra_b, dtype=np.int64) % extra_n
    out["bonds"] = np.concatenate([arrays["bonds"], np.stack([n + ring, n + (ring + 1) % extra_n], axis=1)])
    out["bond_material"] = grow("bond_material", 0, extra_b)
    for name in ("bond_area", "bond_I", "bond_J", "bond_radius"):
        out[name] = grow(name, 0.0, extra_b)
    out["bond_length"] = grow("bond_length", 1.0, extra_b)
    return out


@functools.lru_cache(maxsize=16)
def contact_params(E: float, nu: float, friction: float, restitution: float, dtype: str,
                   damping: bool) -> contact_mod.ContactParams:
    """:func:`jaxbpm.physics.contact.contact_params` as one small compiled program, cached per material.

    Args:
        E: the particles' Young's modulus (Pa).
        nu: the particles' Poisson's ratio.
        friction: the contacts' friction coefficient (``inf``: no sliding).
        restitution: the coefficient of restitution.
        dtype: the name of the floating-point type of the parameters (``"float64"``).
        damping: whether the normal force has its viscous part.

    Returns:
        The contact parameters, arrays of ``dtype``.
    """
    a = lambda v: np.asarray(v, dtype)  # noqa: E731
    return _contact_params_jit(a(E), a(nu), a(friction), a(restitution), damping=damping)


_contact_params_jit = jax.jit(contact_mod.contact_params, static_argnames=("damping",))
