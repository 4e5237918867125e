"""The answer does not depend on how a sample is written down: particle order, bond order (and the order within a
bond), a rigid translation, and a uniform change of scale (the stiffness scales with the length, the modulus does not
change) leave every solver's answer unchanged: 1e-9 relative for the static solvers (DSM, STE), 1e-6 for the DEM."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm.scenes import UniaxialCompression

MATERIALS = {"E": 1e9, "nu": 0.25}
SCENE = UniaxialCompression(strain=0.002)
TOL = {"dsm": 1e-9, "ste": 1e-9, "dem": 1e-6}


def _sample(positions, radii, bonds, bond_radius):
    return jaxbpm.Sample.from_arrays(positions, radii, bonds, bond_radius, materials=MATERIALS, density=2500.0)


@pytest.fixture(scope="module")
def arrays():
    s = jaxbpm.generate.box(150, seed=3, materials=MATERIALS).largest_cluster()
    return (np.asarray(s.positions), np.asarray(s.radii), np.asarray(s.bonds), np.asarray(s.bond_radius))


@pytest.fixture(scope="module")
def reference(arrays):
    s = _sample(*arrays)
    return {m: jaxbpm.solve(s, SCENE, m, **({"transits": 10} if m == "dem" else {})) for m in TOL}


def _transformed(arrays, how):
    pos, rad, bonds, br = arrays
    rng = np.random.default_rng(7)
    if how == "particle order":
        perm = rng.permutation(len(pos))
        where = np.argsort(perm)  # new index of each old particle
        return _sample(pos[perm], rad[perm], where[bonds], br), 1.0
    if how == "bond order":
        order = rng.permutation(len(bonds))
        return _sample(pos, rad, bonds[order][:, ::-1], br[order]), 1.0
    if how == "translation":
        return _sample(pos + np.array([0.37, -1.2, 2.5]), rad, bonds, br), 1.0
    scale = 7.0
    return _sample(pos * scale, rad * scale, bonds, br * scale), scale


@pytest.mark.parametrize("method", list(TOL))
@pytest.mark.parametrize("how", ["particle order", "bond order", "translation", "scale"])
def test_the_answer_does_not_depend_on_how_the_sample_is_written(arrays, reference, method, how):
    sample, scale = _transformed(arrays, how)
    result = jaxbpm.solve(sample, SCENE, method, **({"transits": 10} if method == "dem" else {}))
    ref = reference[method]
    # K = E A / l scales with the length; E does not change
    np.testing.assert_allclose(result.stiffness, scale * ref.stiffness, rtol=TOL[method])
    np.testing.assert_allclose(result.youngs_modulus, ref.youngs_modulus, rtol=TOL[method])
    assert result.status == ref.status == "converged"
