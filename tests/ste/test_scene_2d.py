"""The STE on two-dimensional samples (discs, the translations-only form): exact on a clamped square lattice,
plane-stress moduli of the 2D Voigt tensor, close to the DSM on a random disc packing."""

import jax
import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.generate import disc_packing, lattice
from jaxbpm.physics.model import build_model, default_params
from jaxbpm.scenes import UniaxialCompression
from jaxbpm.ste import tensor

T = 0.5


@pytest.mark.parametrize("cells,axis", [((5, 7), 1), ((8, 5), 0), ((12, 20), 1)])
def test_clamped_square_lattice_is_exact(cells, axis):
    s = lattice("square", cells, 1e-3, thickness=T, materials={"E": 2e9, "nu": 0.3})
    kn = float(build_model(s).stiffness(default_params(s)).kn[0])
    r = jaxbpm.solve(s, UniaxialCompression(axis=axis), "ste")
    expected = cells[1 - axis] * kn / (cells[axis] - 1)  # columns in parallel of bonds in series
    assert abs(r.stiffness / expected - 1) < 1e-9
    assert np.asarray(r.stats["tensor"]).shape == (3, 3) and r.stats["E_z"] is None
    assert abs(r.stats["E_axis"] / (kn / T) - 1) < 1e-9  # k_n per 2R x t cell over its length 2R


def test_plane_stress_moduli_and_isotropic_fit():
    E, nu = 3e9, 0.27
    c = E / (1 - nu**2) * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])
    m = tensor.moduli(c)
    assert np.allclose(m["E"], E, rtol=1e-12) and np.isclose(m["nu"][0, 1], nu, rtol=1e-12)
    assert np.isclose(m["G"][0], E / (2 * (1 + nu)), rtol=1e-12)
    e_fit, nu_fit = tensor.isotropic_fit(c)
    assert np.isclose(e_fit, E, rtol=1e-12) and np.isclose(nu_fit, nu, rtol=1e-12)
    assert np.allclose(tensor.voigt(tensor.tensor_from_voigt(c)), c)


def test_close_to_the_dsm_on_a_disc_packing():
    jax.config.update("jax_enable_x64", True)
    s = disc_packing(400, "rectangle", aspect=(1, 1.5), seed=1).largest_cluster()
    scene = UniaxialCompression(axis=1)
    ste = jaxbpm.solve(s, scene, "ste")
    dsm = jaxbpm.solve(s, scene, "dsm")
    # the STE's local-independence approximation: on 3D random packings it lands within about 10-20 % of the DSM
    assert abs(ste.stiffness / dsm.stiffness - 1) < 0.3
    local = tensor.local_tensors(*jaxbpm.ste.scene._estimator_for(s, scene, jaxbpm.STE())[:1],
                                 default_params(s))
    assert local.shape[1:] == (3, 3)


def test_gradient_matches_finite_differences():
    s = disc_packing(120, seed=3).largest_cluster()
    f = jaxbpm.ste.stiffness_function(s, UniaxialCompression(axis=1))
    p = default_params(s)
    g = jax.grad(f)(p)
    for key, step in (("bond_E", 1e3), ("bond_nu", 1e-6)):
        up, dn = ({**p, key: p[key] + sgn * step} for sgn in (1, -1))
        fd = (float(f(up)) - float(f(dn))) / (2 * step)
        assert abs(float(g[key][0]) / fd - 1) < 1e-5, key


def test_rotations_refused_in_2d():
    with pytest.raises(SceneError, match="dofs=6"):
        jaxbpm.solve(lattice("square", (4, 5)), UniaxialCompression(axis=1), "ste", dofs=6)
