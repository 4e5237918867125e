"""Pure functions of the parameters (:mod:`jaxbpm.dsm.functions`): gradients, load cases, vmap."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import dsm
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression
from tests.dsm.conftest import KN, R


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


def test_three_load_cases_share_one_operator(column):
    k = dsm.load_cases(column, UniaxialCompression(strain=0.002), np.eye(3))
    np.testing.assert_allclose(k[2, 2], 9 * KN / 5, rtol=1e-6)  # pulling the top layer up takes an upward force
    assert abs(k[0, 0]) > 0 and abs(k[0, 0] - k[1, 1]) < 1e-6 * abs(k[0, 0])  # shear x and y alike by symmetry
    np.testing.assert_allclose(k - np.diag(np.diag(k)), 0.0, atol=1e-9 * abs(k[2, 2]))


def test_nonlinear_dsm_is_a_pure_differentiable_function(packing):
    """Contacts: the nonlinear solve as params -> K, jit/vmap-able, its gradient (implicit, at each load step's
    equilibrium) equal to central finite differences with respect to the bond and the contact modulus; the same K
    as jaxbpm.solve."""
    scene = UniaxialCompression(strain=0.002, contacts=True)
    f = dsm.stiffness_function(packing, scene, jaxbpm.DSM(dofs=3, tol=1e-10, load_steps=2))
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


@pytest.mark.filterwarnings("ignore:linear contacts:UserWarning")  # the packing overlaps at rest
def test_linear_contacts_gradient_matches_finite_differences(packing):
    """The linear law's E* and k_n / k_s as params: the implicit gradient of the nonlinear DSM's K against central
    finite differences (stiffer contacts, stiffer sample; a larger kratio, softer shear springs, a softer sample)."""
    scene = UniaxialCompression(strain=0.002, contacts=True, contact_law="linear")
    f = dsm.stiffness_function(packing, scene, jaxbpm.DSM(dofs=3, tol=1e-10, load_steps=2))
    p = dict(default_params(packing), contact_emod=jnp.asarray(1e9), contact_kratio=jnp.asarray(1.21))
    grad = jax.grad(f)(p)
    for key in ("contact_emod", "contact_kratio"):
        x = float(p[key])
        h = 1e-4 * x
        fd = (f({**p, key: jnp.asarray(x + h)}) - f({**p, key: jnp.asarray(x - h)})) / (2 * h)
        np.testing.assert_allclose(float(grad[key]), float(fd), rtol=1e-5)
    assert float(grad["contact_emod"]) > 0 > float(grad["contact_kratio"])


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


def test_deprecated_keywords_map_onto_the_options(column):
    """The former keywords still work for one release, each with a DeprecationWarning naming the DSM field it sets,
    and give the function of the options object (``tol`` was the CG's ``linear_tol``); bad options are refused."""
    import pytest

    scene = UniaxialCompression(strain=0.002)
    p = default_params(column)
    k = float(dsm.stiffness_function(column, scene, jaxbpm.DSM(linear_tol=1e-9, stiffness_tol=None))(p))
    with pytest.warns(DeprecationWarning) as record:
        f = dsm.stiffness_function(column, scene, tol=1e-9, stiffness_tol=None)
    messages = sorted(str(w.message) for w in record if w.category is DeprecationWarning)
    assert len(messages) == 2 and "jaxbpm.DSM(stiffness_tol=...)" in messages[0]
    assert messages[1].startswith("stiffness_function(tol=...)") and "jaxbpm.DSM(linear_tol=...)" in messages[1]
    assert float(f(p)) == k
    np.testing.assert_allclose(k, 9 * KN / 5, rtol=1e-6)
    with pytest.warns(DeprecationWarning, match=r"DSM\(tol="):
        dsm.functions._options_from(None, {"nonlinear_tol": 1e-8})
    assert dsm.functions._options_from(jaxbpm.DSM(dofs=3), {}) == jaxbpm.DSM(dofs=3)
    with pytest.raises(TypeError, match="unexpected keyword argument 'linear_tol'"):
        dsm.stiffness_function(column, scene, linear_tol=1e-9)
    with pytest.raises(jaxbpm.errors.OptionsError, match="geometric_correction"):
        dsm.stiffness_function(column, scene, jaxbpm.DSM(geometric_correction=True))
    with pytest.raises(jaxbpm.errors.OptionsError, match="jaxbpm.DSM options"):
        dsm.stiffness_function(column, scene, jaxbpm.STE())
