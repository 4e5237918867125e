"""What a scene prescribes (:mod:`jaxbpm.dsm.boundary`): a cluster that nothing holds is reported."""

import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.scenes import UniaxialCompression
from tests.dsm.conftest import R


def test_floating_cluster_is_reported(column):
    pos = np.concatenate([np.asarray(column.positions), [[0.1, 0.1, 0.005], [0.1, 0.1 + 2 * R, 0.005]]])
    n = column.n_particles
    bonds = np.concatenate([np.asarray(column.bonds), [[n, n + 1]]])
    s = jaxbpm.Sample.from_arrays(pos, R, bonds, bond_radius_ratio=0.5)
    with pytest.raises(SceneError, match=r"singular: 2 particles .*floating.*\[%d, %d\]" % (n, n + 1)):
        jaxbpm.solve(s, UniaxialCompression(strain=0.002), method="dsm")
