"""VTU time series for ParaView: one ``.vtu`` per time (meshio) and a ``.pvd`` collection."""

from __future__ import annotations

import pathlib
from typing import Any, Iterable, Mapping

import numpy as np

from jaxbpm._atomic import atomic_write
from jaxbpm._vtk import points_3d, user_data
from jaxbpm.errors import SampleError, SampleFileError
from jaxbpm.interop._meta import exact_text
from jaxbpm.sample import Sample


class VTUSeries:
    """A VTU time series for ParaView: one ``<stem>_NNNNNN.vtu`` per :meth:`write` (through meshio) and the
    collection ``<stem>.pvd`` (rewritten atomically after every step, so it is valid even if a run stops).

    Each step: points = particle centres (``positions`` or reference + ``displacement``), a ``vertex`` cell per
    particle and a ``line`` cell per bond (broken bonds stay, with ``intact`` 0 and ``broken`` 1, so every step has
    the same cells).
    Point data: ``radius``, ``displacement`` [m], ``broken_bonds`` (count per particle), ``coordination`` (intact
    bonds), ``type`` (``Sample.types``), then ``point_data`` (e.g. velocity, force, local stiffness). Cell data per
    bond: ``intact``, ``broken``, ``material``, then ``bond_data`` (e.g. force, break_mode); vertex cells carry NaN
    (-1 for integers).
    """

    def __init__(self, pvd_path, sample: Sample):
        if not isinstance(sample, Sample):
            raise TypeError(f"VTUSeries expects a jaxbpm Sample, got {type(sample).__name__}")
        self.path = pathlib.Path(pvd_path)
        if self.path.suffix.lower() != ".pvd":
            raise SampleFileError(f"{self.path}: a VTU series is named by its .pvd collection file")
        if not self.path.parent.is_dir():
            raise SampleFileError(f"{self.path}: no such directory {self.path.parent}")
        self.sample = sample
        self.steps: list[tuple[float, str]] = []

    def write(self, time: float, *, positions=None, displacement=None, intact=None,
              point_data: Mapping[str, Any] | None = None, bond_data: Mapping[str, Any] | None = None) -> pathlib.Path:
        """Write one step (atomically) and update the collection.

        Args:
          time: the step's time [s].
          positions, displacement, intact, point_data, bond_data: see :func:`step_arrays`.

        Returns:
          The step's ``.vtu`` path.
        """
        import meshio

        s = self.sample
        n, nb = s.n_particles, s.n_bonds
        pos, pdata, bdata = step_arrays(s, "VTUSeries.write", positions, displacement, intact, point_data,
                                        bond_data)
        b = np.asarray(s.bonds)
        cells = [("vertex", np.arange(n, dtype=np.int64)[:, None])]
        if nb:
            cells.append(("line", b.astype(np.int64)))
        cell_data = {}
        for name, arr in bdata.items():
            integer = np.issubdtype(arr.dtype, np.integer)
            filler = np.full((n,) + arr.shape[1:], -1 if integer else np.nan, dtype=arr.dtype)
            cell_data[name] = [filler, arr] if nb else [filler]
        mesh = meshio.Mesh(pos, cells, point_data=pdata, cell_data=cell_data)
        vtu = self.path.with_name(f"{self.path.stem}_{len(self.steps):06d}.vtu")
        atomic_write(vtu, lambda tmp: meshio.write(tmp, mesh, file_format="vtu"))
        self.steps.append((float(time), vtu.name))
        self._write_pvd()
        return vtu

    def _write_pvd(self) -> None:
        import xml.etree.ElementTree as ET

        root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
        coll = ET.SubElement(root, "Collection")
        for t, name in self.steps:
            ET.SubElement(coll, "DataSet", timestep=exact_text(t), group="", part="0", file=name)
        tree = ET.ElementTree(root)
        ET.indent(tree)
        atomic_write(self.path, lambda tmp: tree.write(tmp, encoding="utf-8", xml_declaration=True))


def step_arrays(s: Sample, who: str, positions, displacement, intact, point_data, bond_data):
    """The points, point data and bond data of one step of a series (see :class:`VTUSeries`).

    Args:
      s: the series' sample.
      who: the caller, for messages.
      positions: ``[n, 3]`` particle centres [m] (``[n, 2]``: a two-dimensional sample, written at z = 0), or
        ``None``.
      displacement: ``[n, 3]`` (2D: ``[n, 2]``) from the sample's positions [m], or ``None`` (not both with
        ``positions``).
      intact: ``[nb]`` booleans, or ``None`` (all intact).
      point_data: ``{name: [n] or [n, k]}`` extra per-particle fields, or ``None``.
      bond_data: ``{name: [nb] or [nb, k]}`` extra per-bond fields, or ``None``.

    Returns:
      ``(points [n, 3], point data, bond data)``.

    Raises:
      SampleError: a wrong shape, both ``positions`` and ``displacement``, or a bad user field.
    """
    n, nb = s.n_particles, s.n_bonds
    ref = np.asarray(s.positions, np.float64)
    dim = ref.shape[1]  # 2: discs, written at z = 0
    if positions is not None and displacement is not None:
        raise SampleError(f"{who}: give positions or displacement, not both")
    if positions is not None:
        pos = np.asarray(positions, np.float64)
        if pos.shape != (n, dim):
            raise SampleError(f"{who}: positions must have shape [{n}, {dim}], got {pos.shape}")
        disp = pos - ref
    else:
        disp = np.zeros((n, dim)) if displacement is None else np.asarray(displacement, np.float64)
        if disp.shape != (n, dim):
            raise SampleError(f"{who}: displacement must have shape [{n}, {dim}], got {disp.shape}")
        pos = ref + disp
    pos, disp = points_3d(pos), points_3d(disp)
    ok = np.ones(nb, bool) if intact is None else np.asarray(intact, bool).reshape(-1)
    if ok.shape != (nb,):
        raise SampleError(f"{who}: intact must have shape [{nb}], got {ok.shape}")
    b = np.asarray(s.bonds)
    broken = np.bincount(b[~ok].ravel(), minlength=n).astype(np.int32)
    pdata = {"radius": np.asarray(s.radii, np.float64), "displacement": disp, "broken_bonds": broken,
             "coordination": np.bincount(b[ok].ravel(), minlength=n).astype(np.int32),
             "type": np.ones(n, np.int32) if s.types is None else np.asarray(s.types, np.int32)}
    pdata.update(user_data("point_data", point_data, n, "particle", set(pdata)))
    bdata = {"intact": ok.astype(np.int32), "broken": (~ok).astype(np.int32),
             "material": np.asarray(s.bond_material, np.int32)}
    bdata.update({k: v.astype(np.float64) for k, v in
                  user_data("bond_data", bond_data, nb, "bond", set(bdata)).items()})
    return pos, pdata, bdata


def write_vtu_series(pvd_path, sample: Sample, frames: Iterable[Mapping[str, Any]]) -> pathlib.Path:
    """Write a VTU series.

    Args:
      pvd_path: the ``.pvd`` collection file (the ``.vtu`` files go beside it).
      sample: the sample the frames belong to.
      frames: mappings with ``time`` and the keywords of :meth:`VTUSeries.write`.

    Returns:
      The ``.pvd`` path.

    Raises:
      SampleError: a frame without ``time``, or no frames.
    """
    series = VTUSeries(pvd_path, sample)
    for frame in frames:
        frame = dict(frame)
        if "time" not in frame:
            raise SampleError("write_vtu_series: every frame needs a 'time'")
        series.write(frame.pop("time"), **frame)
    if not series.steps:
        raise SampleError("write_vtu_series: no frames")
    return series.path
