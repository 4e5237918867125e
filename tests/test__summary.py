"""What ``Sample.summary()`` reports (:mod:`jaxbpm._summary`), importable from :mod:`jaxbpm.sample` as before."""

import numpy as np

import jaxbpm
from jaxbpm._summary import SampleSummary
from jaxbpm.sample import Sample


def test_summary_counts_and_its_table():
    assert jaxbpm.sample.SampleSummary is SampleSummary and jaxbpm.SampleSummary is SampleSummary
    pos = np.array([[0.0, 0, 0], [2, 0, 0], [4, 0, 0], [10, 0, 0]])
    s = Sample.from_arrays(pos, 1.0, [[0, 1], [1, 2]], bond_radius_ratio=0.5).summary()
    assert isinstance(s, SampleSummary)
    assert (s.n_particles, s.n_bonds, s.n_unbonded, s.n_clusters, s.largest_cluster) == (4, 2, 1, 2, 3)
    assert (s.coordination_min, s.coordination_max) == (0, 2) and np.isclose(s.coordination_mean, 1.0)
    text = str(s)
    assert "particles            4" in text and "clusters             2  (largest 3 particles)" in text
    assert "unbonded particles   1" in text
