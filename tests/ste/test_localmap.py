"""The local stiffness map (:mod:`jaxbpm.ste.localmap`) and its files."""

import h5py
import numpy as np
import pytest

import jaxbpm
from jaxbpm import ste


def test_local_map_files(packing, tmp_path):
    lm = ste.local_map(packing)
    assert lm.E.shape == (packing.n_particles, 3) and np.isfinite(lm.E).mean() > 0.95
    np.testing.assert_allclose(np.nanmean(lm.deviation, axis=0), 0.0, atol=1e-12)
    assert np.nanmax(np.abs(lm.deviation)) < 1.0
    path = jaxbpm.io.save_local_map(tmp_path / "map.h5", lm)
    with h5py.File(path) as f:
        np.testing.assert_array_equal(f["E"][...], lm.E)
        assert f.attrs["format"] == "jaxbpm-ste-map"
    import meshio

    mesh = meshio.read(jaxbpm.io.export_local_map_vtk(tmp_path / "map.vtu", packing, lm))
    np.testing.assert_allclose(mesh.point_data["deviation"], lm.deviation)
    png = jaxbpm.io.plot_local_map(tmp_path / "map.png", lm)
    assert png.stat().st_size > 1000
    with pytest.raises(AttributeError, match="no_such_thing"):
        ste.no_such_thing
