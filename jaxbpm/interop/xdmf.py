"""XDMF companions of sample files: ParaView (and VisIt, meshio) open a jaxbpm HDF5 sample through a small XML file.

XDMF 3 describes heavy data that stays in HDF5: ``write_xdmf("sample.h5")`` writes ``sample.xdmf`` next to it, one
uniform grid whose points are the particle centres (``/positions``) and whose cells are the bonds (``/bonds``, a
two-node polyline each), with per-particle ``radius``, ``mass``, ``coordination`` and ``type`` and per-bond
``bond_radius``, ``material`` and ``length`` attributes: nothing is copied. In ParaView open the ``.xdmf`` file
(reader "XDMF Reader" / "Xdmf3ReaderS"), glyph the points with spheres scaled by ``radius`` and show the lines as tubes.

XDMF was chosen over H5MD because it is the format ParaView, VisIt and meshio all read without plug-ins and it needs no
change to the sample file (H5MD would need its own group layout, and ParaView reads it only through a plug-in).
"""

from __future__ import annotations

import pathlib
from xml.sax.saxutils import quoteattr

import numpy as np

from jaxbpm.errors import SampleError, SampleFileError

__all__ = ["write_xdmf"]

# (attribute name, dataset in the sample file, centre): what the grid shows besides positions and bonds
_POINT = [("radius", "/radii"), ("mass", "/derived/mass"), ("coordination", "/derived/coordination"),
          ("type", "/types")]  # (files written before /types existed: no type)
_CELL = [("bond_radius", "/bond_radius"), ("material", "/bond_material"), ("length", "/derived/bond_length")]


def write_xdmf(sample_path, xdmf_path=None) -> pathlib.Path:
    """Write the XDMF 3 companion of a sample file, atomically.

    It refers to the sample file by its name, so keep the two side by side. A 2D sample's discs are an ``XY``
    geometry (ParaView puts them at z = 0).

    Args:
      sample_path: the HDF5 sample file (:func:`jaxbpm.io.save_sample`).
      xdmf_path: the companion; default the same name with ``.xdmf``.

    Returns:
      The companion's path.

    Raises:
      SampleFileError: the sample file cannot be read (see :func:`jaxbpm.io.load_sample`).
      SampleError: the sample has no bonds (an XDMF grid needs cells; use :func:`jaxbpm.io.export_vtk`).
    """
    import h5py

    from jaxbpm import io

    sample_path = pathlib.Path(sample_path)
    sample = io.load_sample(sample_path)  # (validated, its checksums checked)
    if sample.n_bonds == 0:
        raise SampleError(f"{sample_path}: the sample has no bonds, and an XDMF grid needs cells: export it with "
                          "jaxbpm.io.export_vtk instead")
    target = sample_path.with_suffix(".xdmf") if xdmf_path is None else pathlib.Path(xdmf_path)
    with h5py.File(sample_path, "r") as f:
        shapes = {name: (f[name].shape, f[name].dtype) for _, name in _POINT + _CELL + [("", "/positions"),
                                                                                       ("", "/bonds")]
                  if name in f}
    if "/derived/mass" not in shapes:
        raise SampleFileError(f"{sample_path}: the file has no /derived group (written by another program?): save "
                              "it again with jaxbpm.io.save_sample")
    ref = sample_path.name if target.parent.resolve() == sample_path.parent.resolve() else str(sample_path.resolve())

    def item(name):
        shape, dtype = shapes[name]
        kind = "Int" if np.issubdtype(dtype, np.integer) else "Float"
        dims = " ".join(str(d) for d in shape)
        return (f'<DataItem Dimensions="{dims}" NumberType="{kind}" Precision="{dtype.itemsize}" Format="HDF">'
                f"{ref}:{name}</DataItem>")

    def attribute(label, name, centre):
        return (f'   <Attribute Name={quoteattr(label)} AttributeType="Scalar" Center="{centre}">{item(name)}'
                "</Attribute>")

    lines = ['<?xml version="1.0" ?>', '<Xdmf Version="3.0">', " <Domain>",
             f'  <Grid Name={quoteattr(sample_path.stem)} GridType="Uniform">',
             f'   <Topology TopologyType="Polyline" NodesPerElement="2" NumberOfElements="{sample.n_bonds}">'
             f"{item('/bonds')}</Topology>",
             f'   <Geometry GeometryType="{"XY" if shapes["/positions"][0][1] == 2 else "XYZ"}">'
             f'{item("/positions")}</Geometry>']
    lines += [attribute(label, name, "Node") for label, name in _POINT if name in shapes]
    lines += [attribute(label, name, "Cell") for label, name in _CELL if name in shapes]
    lines += ["  </Grid>", " </Domain>", "</Xdmf>", ""]

    def write(tmp):
        pathlib.Path(tmp).write_text("\n".join(lines), encoding="utf-8")

    return io.atomic_write(target, write)
