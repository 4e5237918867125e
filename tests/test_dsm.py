"""Direct stiffness method: closed forms, agreement with the DEM, gradients, linearity, failure reports."""

import dataclasses
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import ConvergenceError, SceneError, dsm
from jaxbpm.physics import blocks
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression

R = 1e-3
# one xdist worker for the tests that solve `packing` (or a sample of its size class) with contacts: they share the
# compiled nonlinear solve with contacts, the DEM's run with contacts and the linear solves
_SHARED = "dsm-packing-contacts"
KN = 1e9 * np.pi * (0.5 * R) ** 2 / (2 * R)


@pytest.fixture(scope="module")
def column():
    return jaxbpm.generate.lattice("sc", (3, 3, 6), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


@pytest.fixture(scope="module")
def packing():
    s = jaxbpm.generate.box(200, seed=3, mean_radius=R, packing_fraction=0.5)
    return s.largest_cluster()


@pytest.mark.parametrize("dofs", [3, 6])
def test_simple_cubic_lattice_is_exact(column, dofs):
    res = jaxbpm.solve(column, UniaxialCompression(strain=0.002), method="dsm", dofs=dofs)
    assert res.stats["converged"] and res.stats["dofs"] == dofs
    np.testing.assert_allclose(res.stiffness, 9 * KN / 5, rtol=1e-6)
    np.testing.assert_allclose(res.youngs_modulus, KN / (2 * R), rtol=1e-6)


def test_dsm_in_float32_agrees_with_float64(packing):
    # the bond-geometry split is exact up to rounding: float32's rounding must not be taken for a changed bond law
    scene = UniaxialCompression(strain=0.002)
    ref = jaxbpm.solve(packing, scene, method="dsm").stiffness
    with jax.enable_x64(False), warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the float32 warning
        res = jaxbpm.solve(packing, scene, method="dsm", tol=1e-5)
    assert res.stats["converged"]
    assert abs(res.stiffness / ref - 1) < 1e-3, (res.stiffness, ref)


def test_dsm_matches_dem_bonds_only(packing):
    scene = UniaxialCompression(strain=0.002)
    a = jaxbpm.solve(packing, scene, method="dsm")
    b = jaxbpm.solve(packing, scene, method="dem")
    assert abs(a.stiffness / b.stiffness - 1) < 1e-2, (a.stiffness, b.stiffness)


@pytest.mark.parametrize("scene", [
    # (with contacts alone: the nonlinear solve of the linearised-contacts tests, compiled once on one worker)
    pytest.param(UniaxialCompression(strain=0.002, contacts=True), marks=pytest.mark.xdist_group(_SHARED)),
    UniaxialCompression(strain=0.002, boundary="walls"),
    UniaxialCompression(strain=0.002, boundary="walls", contacts=True)], ids=["contacts", "walls", "contacts+walls"])
def test_nonlinear_dsm_matches_dem(packing, scene):
    a = jaxbpm.solve(packing, scene, method="dsm")
    b = jaxbpm.solve(packing, scene, method="dem")
    assert a.stats["converged"] and a.stats["nonlinear"]
    assert abs(a.stiffness / b.stiffness - 1) < 6e-2, (a.stiffness, b.stiffness)


@pytest.mark.xdist_group(_SHARED)
def test_sliding_contacts_match_the_dem_where_no_slip_does_not(packing):
    # stiff particles, soft bonds: contacts carry the load and most of them slide in the DEM (friction 0.5)
    s = jaxbpm.generate.box(200, seed=3, mean_radius=R, packing_fraction=0.5, materials={"E": 1e8, "nu": 0.25},
                            particle_material={"E": 1e10, "nu": 0.25, "density": 2500.0, "friction": 0.5,
                                               "restitution": 0.5}).largest_cluster()
    scene = UniaxialCompression(strain=0.005, contacts=True)
    dem = jaxbpm.solve(s, scene, method="dem")
    slip = jaxbpm.solve(s, scene, method="dsm")
    stick = jaxbpm.solve(s, scene, method="dsm", slip=False, throw=False)
    assert stick.status == "max_iterations"  # Newton stalls without slip here (a known limit)
    assert slip.stats["slip"] and not stick.stats["slip"]
    err_slip, err_stick = slip.stiffness / dem.stiffness - 1, stick.stiffness / dem.stiffness - 1
    assert abs(err_slip) < 0.03 and err_stick > 0.1, (err_slip, err_stick)
    # with a friction no contact reaches, the two are the same law (on a sample where both converge tightly)
    scene = UniaxialCompression(strain=0.002, contacts=True)
    rough = packing.replace(particle_material=dataclasses.replace(packing.particle_material, friction=1e3))
    a = jaxbpm.solve(rough, scene, method="dsm", tol=1e-6)
    b = jaxbpm.solve(packing, scene, method="dsm", slip=False, tol=1e-6)
    assert a.stats["converged"] and b.stats["converged"]
    np.testing.assert_allclose(a.stiffness, b.stiffness, rtol=1e-5)


@pytest.mark.xdist_group(_SHARED)
def test_linear_dsm_linearises_the_contacts(packing):
    # stiffer particles: the contacts carry ~20 % of the stiffness (the nonlinear DSM is the reference here: it
    # matches the DEM with contacts, test_nonlinear_dsm_matches_dem)
    s = packing.replace(particle_material=dataclasses.replace(packing.particle_material, E=5e9))
    scene = UniaxialCompression(strain=0.002, contacts=True)
    ref = jaxbpm.solve(s, scene, method="dsm")
    bonds = jaxbpm.solve(s, UniaxialCompression(strain=0.002), method="dsm")
    lin = jaxbpm.solve(s, scene, method="dsm", nonlinear=False)
    assert not lin.stats["nonlinear"] and lin.stats["contact_candidates"] > 0 and lin.stats["converged"]
    assert ref.stats["converged"]
    share = 1 - bonds.stiffness / ref.stiffness  # the contacts' share of the stiffness
    err = lin.stiffness / ref.stiffness - 1
    assert share > 0.1 and abs(err) < share / 3, (share, err)
    # Hertz: a later linearisation point (a larger overlap) is stiffer
    late = jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_fraction=1.0)
    assert late.stiffness > lin.stiffness
    with pytest.raises(SceneError, match="contact_passes"):
        jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_passes=0)
    # the candidates of the linear solve reach only as far as the strain can close a gap (0.01 mean radii here):
    # the pairs left out never touch, so a wider reach gives the same answer (3x: more candidates, the same size
    # class, so the same compiled solve; test_linearised_contacts_widen_a_short_default_reach reaches half a radius)
    r = float(np.mean(s.radii))
    wide = jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_skin=3.0 * lin.stats["contact_skin"])
    assert lin.stats["contact_candidates"] < wide.stats["contact_candidates"]
    assert lin.stats["contacts_touching"] == wide.stats["contacts_touching"] > 0
    assert lin.stats["contact_gap_max"] < 0.5 * lin.stats["contact_skin"] < 0.01 * r
    np.testing.assert_allclose(lin.stiffness, wide.stiffness, rtol=1e-9)
    # a reach that misses touching pairs is reported
    with pytest.warns(UserWarning, match="contact_skin"):
        jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_skin=0.9 * lin.stats["contact_gap_max"])


@pytest.mark.xdist_group(_SHARED)
def test_linearised_contacts_widen_a_short_default_reach(packing, monkeypatch):
    s = packing.replace(particle_material=dataclasses.replace(packing.particle_material, E=5e9))
    scene = UniaxialCompression(strain=0.002, contacts=True)
    wide = jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_skin=0.5 * float(np.mean(s.radii)))
    # a default reach of one affine approach (a quarter of the default): touching pairs lie near it, so it doubles
    # until they do not
    monkeypatch.setattr(dsm.scene, "LINEAR_REACH", 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        short = jaxbpm.solve(s, scene, method="dsm", nonlinear=False)
    assert short.stats["contact_skin_retries"] >= 1
    assert short.stats["contact_gap_max"] < 0.5 * short.stats["contact_skin"]
    assert short.stats["contacts_touching"] == wide.stats["contacts_touching"]
    np.testing.assert_allclose(short.stiffness, wide.stiffness, rtol=1e-9)


def test_cg_starts_from_a_guess(packing):
    scene = UniaxialCompression(strain=0.002)
    model = scene.model(packing, contacts=False)
    free_np, fixed, driven = dsm.free_mask(model, scene, packing)
    delta = scene.strain * scene.geometry(packing)[0]
    u_p = np.zeros(free_np.shape)
    u_p[driven, scene.axis] = -delta
    free, u_p = jnp.asarray(free_np), jnp.asarray(u_p)
    full, jac = dsm.tangent_operator(model, default_params(packing))
    precond = dsm.build_preconditioner(model, default_params(packing), free, jac)
    cold = dsm.cg(full, precond, free, u_p, 1e-10, None)
    affine = dsm.cg(full, precond, free, u_p, 1e-10, None, x0=dsm.affine_field(packing, model, scene.axis, delta))
    # the same solution from a start closer to it (the guess's prescribed DOFs are not used)
    assert affine[1] <= 1e-10 and int(affine[2]) < int(cold[2]), (int(affine[2]), int(cold[2]))
    scale = np.abs(np.asarray(cold[0])).max(axis=0)  # displacements and rotations apart
    assert np.abs(np.asarray(affine[0] - cold[0]) / scale).max() < 1e-6
    np.testing.assert_allclose(affine[3], cold[3], rtol=1e-12)  # the energy, tracked from the guess's own
    # started at the solution, nothing is left to do
    assert int(dsm.cg(full, precond, free, u_p, 1e-8, None, x0=cold[0])[2]) == 0


@pytest.mark.parametrize("dofs", [3, 6])
def test_symmetrised_jacobians_are_the_symmetric_part(packing, dofs):
    model = UniaxialCompression().model(packing, rotations=dofs == 6)
    jr = dsm.reduced_jacobians(model, default_params(packing))
    np.testing.assert_allclose(dsm.symmetrised(jr), jr, atol=1e-12 * float(jnp.abs(jr).max()))  # bonds at rest
    pairs = jnp.asarray(np.asarray(model.bonds)[:50])
    d = (model.positions0[pairs[:, 1]] - model.positions0[pairs[:, 0]]) * 0.999  # a small overlap
    jc = dsm.contact_jacobians(model, pairs, None, d)
    full, sym = dsm.full_jacobians(jc), dsm.full_jacobians(dsm.symmetrised(jc))
    np.testing.assert_allclose(sym, 0.5 * (full + jnp.swapaxes(full, 1, 2)), atol=1e-12 * float(jnp.abs(full).max()))
    assert float(jnp.abs(full - jnp.swapaxes(full, 1, 2)).max()) > 0  # the preloaded contact is not symmetric


def test_gradient_matches_central_differences():
    s = jaxbpm.generate.lattice("fcc", (2, 2, 3), R, bond_radius_ratio=0.5, materials={"E": [1e9, 2e9], "nu": 0.3})
    s = jaxbpm.generate.mix_materials(s, [0.4, 0.6], seed=1)
    f = jax.jit(dsm.stiffness_function(s, UniaxialCompression(strain=0.002)))
    p = default_params(s)
    g = jax.grad(f)(p)["bond_E"]
    for c in range(2):
        h = 1e-4 * p["bond_E"][c]
        up = {**p, "bond_E": p["bond_E"].at[c].add(h)}
        dn = {**p, "bond_E": p["bond_E"].at[c].add(-h)}
        fd = (f(up) - f(dn)) / (2 * h)
        np.testing.assert_allclose(g[c], fd, rtol=1e-5)
    assert float(g[0]) > 0 and float(g[1]) > 0
    # forward mode: the tangent solves stop on their residual (the energy test belongs to the primal system); one
    # JVP per component (one program, unbatched: cheaper to compile than jacfwd's tangents over every parameter)
    for c in range(2):
        tangent = {"bond_E": jnp.zeros_like(p["bond_E"]).at[c].set(1.0), "bond_nu": jnp.zeros_like(p["bond_nu"])}
        np.testing.assert_allclose(jax.jvp(f, (p,), (tangent,))[1], g[c], rtol=1e-7)
    # vmap over parameter sets: K is linear in a common factor on E
    batch = {"bond_E": p["bond_E"][None, :] * jnp.array([[1.0], [2.0], [3.0]]),
             "bond_nu": jnp.broadcast_to(p["bond_nu"], (3, 2))}
    ks = jax.vmap(f)(batch)
    np.testing.assert_allclose(ks, f(p) * np.array([1.0, 2.0, 3.0]), rtol=1e-9)


def test_stiffness_is_linear_in_common_E(packing):
    scene = UniaxialCompression(strain=0.002)
    a = jaxbpm.solve(packing, scene, method="dsm")
    p = default_params(packing)
    b = jaxbpm.solve(packing, scene, method="dsm", params={**p, "bond_E": 3.0 * p["bond_E"]})
    np.testing.assert_allclose(b.stiffness, 3.0 * a.stiffness, rtol=1e-9)


def test_three_load_cases_share_one_operator(column):
    k = dsm.load_cases(column, UniaxialCompression(strain=0.002), np.eye(3))
    np.testing.assert_allclose(k[2, 2], 9 * KN / 5, rtol=1e-6)  # pulling the top layer up takes an upward force
    assert abs(k[0, 0]) > 0 and abs(k[0, 0] - k[1, 1]) < 1e-6 * abs(k[0, 0])  # shear x and y alike by symmetry
    np.testing.assert_allclose(k - np.diag(np.diag(k)), 0.0, atol=1e-9 * abs(k[2, 2]))


@pytest.mark.xdist_group(_SHARED)
def test_non_convergence_is_reported(packing):
    scene = UniaxialCompression(strain=0.002, contacts=True)
    # failure as data: the status, no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = jaxbpm.solve(packing, scene, method="dsm", newton_maxiter=1, tol=1e-12, throw=False)
    assert res.status == "max_iterations" and not res.ok and "relative residual" in res.stats["failure"]
    assert res.stats["converged"] is False and res.stats["residual"] > 1e-12
    # throw=True is the default: the error carries the result
    with pytest.raises(ConvergenceError, match="relative residual") as err:
        jaxbpm.solve(packing, scene, jaxbpm.DSM(newton_maxiter=1, tol=1e-12))
    assert err.value.result.status == "max_iterations" and err.value.result.stiffness == res.stiffness
    # the linear solve too, with an iteration budget too small for its tolerance
    lin = jaxbpm.solve(packing, UniaxialCompression(strain=0.002), "dsm", maxiter=2, stiffness_tol=None, throw=False)
    assert lin.status == "max_iterations" and lin.stats["iterations"] == 2
    with pytest.raises(ConvergenceError):
        jaxbpm.solve(packing, UniaxialCompression(strain=0.002), "dsm", maxiter=2, stiffness_tol=None)
    ok = jaxbpm.solve(packing, UniaxialCompression(strain=0.002), "dsm")
    assert ok.status == "converged" and ok.ok


def test_floating_cluster_is_reported(column):
    pos = np.concatenate([np.asarray(column.positions), [[0.1, 0.1, 0.005], [0.1, 0.1 + 2 * R, 0.005]]])
    n = column.n_particles
    bonds = np.concatenate([np.asarray(column.bonds), [[n, n + 1]]])
    s = jaxbpm.Sample.from_arrays(pos, R, bonds, bond_radius_ratio=0.5)
    with pytest.raises(SceneError, match=r"singular: 2 particles .*floating.*\[%d, %d\]" % (n, n + 1)):
        jaxbpm.solve(s, UniaxialCompression(strain=0.002), method="dsm")


def test_walls_need_the_nonlinear_solver(column):
    with pytest.raises(SceneError, match="nonlinear"):
        jaxbpm.solve(column, UniaxialCompression(boundary="walls"), method="dsm", nonlinear=False)


@pytest.mark.parametrize("dofs", [3, 6])
def test_element_by_element_operator_equals_the_force_jvp(packing, dofs):
    model = UniaxialCompression().model(packing, rotations=dofs == 6)
    p = default_params(packing)
    v = jnp.asarray(np.random.default_rng(0).normal(size=(model.n, dofs)) * 1e-6)
    ebe, jac = dsm.tangent_operator(model, p, operator="jacobians")
    jvp, none = dsm.tangent_operator(model, p, operator="jvp")
    ni = 9 if dofs == 6 else 3
    assert jac.shape == (ni, ni, model.bonds.shape[0]) and none is None
    a, b = ebe(v), jvp(v)
    np.testing.assert_allclose(a, b, atol=1e-12 * float(jnp.abs(b).max()))
    # the full per-bond Jacobians are symmetric (the bond law has a potential at rest) and give the same product
    full = dsm.bond_jacobians(model, p)
    assert full.shape == (model.bonds.shape[0], 2 * dofs, 2 * dofs)
    np.testing.assert_allclose(full, jnp.swapaxes(full, 1, 2), atol=1e-9 * float(jnp.abs(full).max()))
    bonds = np.asarray(model.bonds)
    z = jnp.concatenate([v[bonds[:, 0]], v[bonds[:, 1]]], axis=1)
    y = jnp.einsum("bij,bj->bi", full, z)
    c = jax.ops.segment_sum(jnp.concatenate([y[:, :dofs], y[:, dofs:]]), jnp.concatenate([bonds[:, 0], bonds[:, 1]]),
                            model.n)
    np.testing.assert_allclose(c, b, atol=1e-12 * float(jnp.abs(b).max()))
    # and each particle's self block is the sum of its bonds' diagonal blocks
    blocks = dsm.block_diagonal(model, p, jac)
    ref = (jax.ops.segment_sum(full[:, :dofs, :dofs], bonds[:, 0], model.n)
           + jax.ops.segment_sum(full[:, dofs:, dofs:], bonds[:, 1], model.n))
    np.testing.assert_allclose(blocks, ref, atol=1e-12 * float(jnp.abs(ref).max()))


def test_coarse_matrix_needs_only_the_coupling_bonds(packing):
    model = UniaxialCompression().model(packing)
    free = dsm.free_mask(model, UniaxialCompression(), packing)[0]
    coarse = dsm.coarse_space(model, free, aggregate_size=25)
    assert 4 <= coarse.count <= 16 and 0 < coarse.bonds.shape[0] < model.bonds.shape[0]
    jac = dsm.reduced_jacobians(model, default_params(packing))
    every = dataclasses.replace(coarse, bonds=jnp.arange(model.bonds.shape[0]))
    a, b = dsm.preconditioner.coarse_factor(model, jac, coarse), dsm.preconditioner.coarse_factor(model, jac, every)
    np.testing.assert_allclose(a @ a.T, b @ b.T, rtol=1e-8, atol=1e-10 * float(jnp.abs(b @ b.T).max()))
    # and it is P^T K_ff P: compare with the operator applied to the coarse basis (one column per rigid mode)
    basis = np.zeros((coarse.count * 6,) + free.shape)
    for a_ in range(coarse.count):
        members = np.asarray(coarse.labels) == a_
        basis[6 * a_:6 * a_ + 6, members] = np.moveaxis(np.asarray(coarse.basis)[members], 2, 0)
    full, _ = dsm.tangent_operator(model, default_params(packing))
    kp = jax.vmap(full)(jnp.asarray(basis))
    direct = jnp.einsum("aij,bij->ab", jnp.asarray(basis), kp)
    d = jnp.diag(direct)
    direct = direct + jnp.diag(jnp.where(d > 0, 1e-10 * d.max(), 1.0))  # the factor's documented shift
    np.testing.assert_allclose(b @ b.T, direct, atol=1e-9 * float(jnp.abs(direct).max()))


@pytest.mark.parametrize("dofs", [3, 6])
def test_bond_geometry_reproduces_the_jacobians_and_the_preconditioner(packing, dofs):
    # two materials with different E and nu: E_b (J_E + s(nu_b) J_G) is the forward-mode Jacobian of the bond law,
    # and the weighed per-material parts are the block diagonal and the coarse matrix assembled from it
    s = jaxbpm.generate.mix_materials(packing, [0.5, 0.5], seed=2, materials={"E": [1e9, 3e9], "nu": [0.2, 0.35]})
    scene = UniaxialCompression(strain=0.002)
    model = scene.model(s, rotations=dofs == 6)
    free = dsm.free_mask(model, scene, s)[0]
    coarse = dsm.coarse_space(model, free, aggregate_size=25)
    geo = dsm.bond_geometry(model, coarse, n_materials=2)
    assert geo.reduced is None  # read by the preconditioner's parts only
    p = default_params(s)
    ref = dsm.reduced_jacobians(model, p)
    jr, jp, _ = dsm.operator.geometric_jacobians(model, p, dsm.bond_geometry(model, coarse))
    scale = float(jnp.abs(ref).max())
    np.testing.assert_allclose(jr, ref, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(jp, dsm.packed_jacobians(ref), rtol=0, atol=1e-12 * scale)
    w = dsm.operator.material_weights(p)
    np.testing.assert_allclose(jnp.einsum("mp,mpnab->nab", w, geo.blocks), dsm.block_diagonal(model, p, ref),
                               rtol=0, atol=1e-12 * scale)
    direct = dsm.preconditioner.coarse_matrix(model, ref, coarse)
    np.testing.assert_allclose(jnp.einsum("mp,mpab->ab", w, geo.coarse), direct, rtol=0,
                               atol=1e-12 * float(jnp.abs(direct).max()))
    # the solve through the geometry equals the one that differentiates the bond law, and so do its gradients
    free_j = jnp.asarray(free)
    u_p = np.zeros(free.shape)
    u_p[~free.all(axis=1) & (np.asarray(s.positions)[:, 2] > np.asarray(s.positions)[:, 2].mean()), 2] = -1e-6

    def k(p, geometry):
        u, _ = dsm.linear_solve(model, p, free_j, jnp.asarray(u_p), tol=1e-10, coarse=coarse, geometry=geometry)
        return jnp.vdot(u, dsm.tangent_operator(model, p)[0](u))

    k_and_grad = jax.jit(jax.value_and_grad(k))  # (one program per operator, not a trace op by op)
    (k_geo, g_geo), (k_ref, g_ref) = k_and_grad(p, geo), k_and_grad(p, None)
    np.testing.assert_allclose(k_geo, k_ref, rtol=1e-9)
    for name in ("bond_E", "bond_nu"):
        np.testing.assert_allclose(g_geo[name], g_ref[name], rtol=1e-7)


@pytest.mark.parametrize("dofs", [3, 6])
def test_setup_over_bond_chunks_equals_the_whole_sample(packing, dofs, monkeypatch):
    # large samples build the bonds' geometric parts chunk by chunk (lax.map over padded chunks): same numbers as
    # one pass over all bonds, the padding cut off
    chunk = blocks.BLOCK
    assert blocks.block_length(7 * chunk) == chunk and blocks.block_length(11 * chunk // 4) == chunk // 4
    assert blocks.block_length(7 * chunk + 1) == chunk  # no divisor: padded
    model = UniaxialCompression(strain=0.002).model(packing, rotations=dofs == 6)
    nb = model.bonds.shape[0]
    whole = jax.jit(dsm.operator._geometry_chunk)(model)
    chunked = jax.jit(lambda m: dsm.operator.over_bonds(dsm.operator._geometry_chunk, m, block=97))(model)
    assert nb % blocks.block_length(nb, 97) != 0 and nb > 2 * 97  # padded
    for a, b in zip(whole, chunked):
        assert a.shape == b.shape and a.shape[-1] == nb
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-14 * float(jnp.abs(a).max()))
    # the preconditioner's parts, sums over bonds and over the coupling bonds, chunk by chunk
    s = jaxbpm.generate.mix_materials(packing, [0.5, 0.5], seed=2, materials={"E": [1e9, 3e9], "nu": [0.2, 0.35]})
    model = UniaxialCompression(strain=0.002).model(s, rotations=dofs == 6)
    free = dsm.free_mask(model, UniaxialCompression(strain=0.002), s)[0]
    coarse = dsm.coarse_space(model, free, aggregate_size=25)
    reduced = dsm.operator._geometry_parts(model)[0]
    parts = dsm.preconditioner._preconditioner_parts.__wrapped__
    ref = jax.jit(parts, static_argnums=3)(model, reduced, coarse, 2)
    monkeypatch.setattr(blocks, "BLOCK", 53)
    assert coarse.bonds.shape[0] > 2 * 53
    got = jax.jit(parts, static_argnums=3)(model, reduced, coarse, 2)
    for a, b in zip(ref, got):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-13 * float(jnp.abs(a).max()))


def test_two_level_preconditioner_same_answer_fewer_iterations(packing):
    scene = UniaxialCompression(strain=0.002)
    # the residual test alone: iterations to the same residual
    a = jaxbpm.solve(packing, scene, method="dsm", preconditioner="jacobi", linear_tol=1e-10, stiffness_tol=None)
    b = jaxbpm.solve(packing, scene, method="dsm", preconditioner="two-level", aggregate_size=25, linear_tol=1e-10,
                     stiffness_tol=None)
    assert a.stats["preconditioner"] == "jacobi" and b.stats["preconditioner"] == "two-level"
    assert b.stats["aggregates"] >= 4
    np.testing.assert_allclose(b.stiffness, a.stiffness, rtol=1e-8)
    assert b.stats["iterations"] < 0.7 * a.stats["iterations"], (a.stats["iterations"], b.stats["iterations"])
    # the energy measure of K and the DEM's boundary measure agree at convergence
    np.testing.assert_allclose(a.stats["stiffness_boundary"], a.stiffness, rtol=1e-7)


@pytest.mark.parametrize("m", [5, 96, 250])
def test_preconditioner_building_blocks_match_dense_linear_algebra(m):
    rng = np.random.default_rng(m)
    # blocked Cholesky substitution (block size 96: one partial block, exactly one block, two full and a partial one)
    x = rng.normal(size=(m, m))
    a = x @ x.T + m * np.eye(m)
    r = rng.normal(size=m)
    got = dsm.CholeskyBlocks.of(jnp.linalg.cholesky(jnp.asarray(a))).solve(jnp.asarray(r))
    np.testing.assert_allclose(got, np.linalg.solve(a, r), rtol=1e-10, atol=1e-12 * np.abs(np.linalg.solve(a, r)).max())


def test_stiffness_tolerance_stops_sooner_within_its_bound(packing):
    scene = UniaxialCompression(strain=0.002)
    tight = jaxbpm.solve(packing, scene, method="dsm", linear_tol=1e-10)
    for stol in (1e-2, 1e-4):
        loose = jaxbpm.solve(packing, scene, method="dsm", stiffness_tol=stol, linear_tol=1e-10)
        assert loose.stats["converged"] and loose.stats["iterations"] < tight.stats["iterations"]
        # the energy of the CG iterate is an upper bound that settles from above
        assert 0 <= loose.stiffness / tight.stiffness - 1 < stol, (stol, loose.stiffness / tight.stiffness - 1)


def test_bad_solver_options_are_named(packing):
    scene = UniaxialCompression(strain=0.002)
    with pytest.raises(ValueError, match="preconditioner"):
        jaxbpm.solve(packing, scene, method="dsm", preconditioner="ilu")
    with pytest.raises(ValueError, match="operator"):
        jaxbpm.solve(packing, scene, method="dsm", operator="dense")
    model = UniaxialCompression(contacts=True).model(packing, contacts=True)
    with pytest.raises(SceneError, match="bonds only"):
        dsm.tangent_operator(model, default_params(packing), operator="jacobians")


def test_nonlinear_dsm_is_a_pure_differentiable_function(packing):
    """Contacts: the nonlinear solve as params -> K, jit/vmap-able, its gradient (implicit, at each load step's
    equilibrium) equal to central finite differences with respect to the bond and the contact modulus; the same K
    as jaxbpm.solve."""
    scene = UniaxialCompression(strain=0.002, contacts=True)
    f = dsm.stiffness_function(packing, scene, dofs=3, nonlinear_tol=1e-10, load_steps=2)
    p = dict(default_params(packing), contact_E=jnp.asarray(float(packing.particle_material.E)))
    k = float(f(p))
    compiled = dsm.newton.newton_program.compilations
    ref = jaxbpm.solve(packing, scene, "dsm", dofs=3, tol=1e-10, load_steps=2, params=p)
    np.testing.assert_allclose(k, ref.stiffness, rtol=1e-9)
    assert dsm.newton.newton_program.compilations == compiled  # the function's program serves the solve
    grad = jax.jit(jax.grad(f))(p)
    for key in ("bond_E", "contact_E"):
        x = np.asarray(p[key], float)
        h = 1e-4 * x
        fd = (f({**p, key: jnp.asarray(x + h)}) - f({**p, key: jnp.asarray(x - h)})) / (2 * h)
        assert dsm.newton.newton_program.compilations == compiled  # (weakly typed or not, the same program)
        np.testing.assert_allclose(np.asarray(grad[key]), fd, rtol=1e-5)
        assert np.all(np.asarray(grad[key]) > 0)  # stiffer bonds or particles, stiffer sample
    batch = {**p, "bond_E": jnp.asarray([[1e9], [2e9]]), "bond_nu": jnp.asarray([[0.25], [0.25]]),
             "contact_E": jnp.asarray([p["contact_E"]] * 2)}
    ks = np.asarray(jax.jit(jax.vmap(f))(batch))
    np.testing.assert_allclose(ks[0], f({**p, "bond_E": jnp.asarray([1e9])}), rtol=1e-9)
    assert ks[1] > ks[0]


_VMAP_REPEATS = """
import sys, jax
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp, jaxbpm
from jaxbpm.scenes import UniaxialCompression
s = jaxbpm.io.load_sample(sys.argv[1])
f = jax.jit(jax.vmap(jaxbpm.dsm.stiffness_function(s, UniaxialCompression(strain=1e-3))))
for i in range(40):
    k = f({"bond_E": jnp.asarray([[1e9], [2e9], [3e9 + i]]), "bond_nu": jnp.full((3, 1), 0.25)})
    assert abs(float(k[1]) / float(k[0]) - 2) < 1e-6, k
print("ok", s.n_particles)
"""


def test_vmap_over_the_two_level_preconditioner_never_hangs(tmp_path):
    """A batched solve with a coarse space of several blocks, 40 times: the batched LAPACK factorisation it used to
    run hung XLA's CPU runtime within 6-16 calls on this sample (all threads idle). In a subprocess, so that a hang
    is a failure, not a stuck suite."""
    import subprocess
    import sys

    path = jaxbpm.io.save_sample(tmp_path / "box.h5", jaxbpm.generate.box(500, seed=0).largest_cluster())
    res = subprocess.run([sys.executable, "-c", _VMAP_REPEATS, str(path)], capture_output=True, text=True,
                         timeout=240)
    assert res.returncode == 0 and res.stdout.startswith("ok"), res.stderr[-2000:]


def test_geometric_correction_is_second_order(packing):
    """The linear bonds-only K corrected by the exact bond law's work along the linear field: within a few 1e-4 of
    the nonlinear DSM at 2 % strain, where the linear K is several 1e-3 stiff; the error shrinks faster than
    the linear one with the strain (second order); a second solve compiles nothing; contacts are refused."""
    errors = {}
    for strain in (0.005, 0.02):
        scene = UniaxialCompression(strain=strain)
        nonlinear = jaxbpm.solve(packing, scene, method="dsm", nonlinear=True).stiffness
        r = jaxbpm.solve(packing, scene, method="dsm", nonlinear=False, geometric_correction=True)
        linear = jaxbpm.solve(packing, scene, method="dsm", nonlinear=False).stiffness
        assert r.stats["stiffness_linear"] == pytest.approx(linear, rel=1e-9)
        assert r.stats["geometric_correction"] == pytest.approx(r.stiffness / linear - 1, rel=1e-9)
        assert len(r.displacement) == len(r.force) == 1 + dsm.linear.CORRECTION_POINTS
        errors[strain] = (abs(linear / nonlinear - 1), abs(r.stiffness / nonlinear - 1))
    lin2, cor2 = errors[0.02]
    assert lin2 > 3e-3 and cor2 < 0.1 * lin2 and cor2 < 5e-4
    lin05, cor05 = errors[0.005]
    assert cor05 < 0.1 * lin05
    assert cor2 / cor05 > lin2 / lin05  # the residual grows faster with the strain than the linear error
    before = dsm.linear.path_work_program.compilations
    again = jaxbpm.solve(packing, UniaxialCompression(strain=0.02), method="dsm", nonlinear=False,
                         geometric_correction=True)
    assert dsm.linear.path_work_program.compilations == before
    assert again.stiffness == pytest.approx(r.stiffness, rel=1e-12)  # (r: the loop's last solve, at 2 %)
    with pytest.raises(SceneError, match="geometric_correction"):
        jaxbpm.solve(packing, UniaxialCompression(strain=0.02, contacts=True), method="dsm", nonlinear=False,
                     geometric_correction=True)
    with pytest.raises(SceneError, match="geometric_correction"):
        jaxbpm.solve(packing, UniaxialCompression(strain=0.02), method="dsm", nonlinear=True,
                      geometric_correction=True)
