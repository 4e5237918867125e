"""Small samples shared by the interoperability tests, and an exact comparison of two samples."""

import jax
import numpy as np

from jaxbpm import generate
from jaxbpm.sample import Domain, Sample


def _sample(n=6, seed=0, **kw):
    rng = np.random.default_rng(seed)
    pos = np.arange(n)[:, None] * np.array([1.0, 0.0, 0.0]) + 0.1 * rng.standard_normal((n, 3))
    bonds = [[i, i + 1] for i in range(n - 1)] + [[0, 2], [3, 5]]
    kw.setdefault("bond_radius", 0.1 + 0.1 * rng.random(len(bonds)))
    return Sample.from_arrays(pos, 0.45 + 0.05 * rng.random(n), bonds, **kw)


def _multi():
    return _sample(bond_material=np.array([0, 1, 2, 1, 0, 2, 1]),
                   materials={"E": [1e9, 2.5e9, 7e10], "nu": [0.2, 0.25, 0.3], "tensile_strength": [1e6, np.inf, 3e7],
                              "shear_strength": [2e6, 5e6, np.inf]},
                   particle_material={"density": 2650.0, "E": 7e10, "nu": 0.17, "friction": 0.3, "restitution": 0.8},
                   bond_contact="replace", domain=Domain("cylinder", (-0.5, -1.0, -1.0), (5.5, 1.0, 1.0)))


def _assert_same(a: Sample, b: Sample):
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    assert ta == tb
    for x, y in zip(la, lb):
        assert np.asarray(x).dtype == np.asarray(y).dtype
        assert np.array_equal(x, y)


def _lattice():
    return generate.lattice("sc", (4, 3, 2), 1e-3)
