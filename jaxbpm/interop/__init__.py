"""Interoperability with other DEM codes: their bond parameter conventions (:mod:`~jaxbpm.interop.conventions`:
PFC, LAMMPS, Yade, MUSEN, translated exactly to and from jaxbpm's bond law), exchange formats
(:mod:`~jaxbpm.interop.formats`: LAMMPS data and dump files, CSV, VTU and VTKHDF series for ParaView, LIGGGHTS and
Yade files), PFC's parameter names for jaxbpm's params both ways (:mod:`~jaxbpm.interop.pfc`) and the
``jaxbpm convert`` / ``jaxbpm params`` commands (:mod:`~jaxbpm.interop.cli`).
"""

import importlib

__all__ = ["conventions", "formats", "pfc"]


def __getattr__(name: str):
    # the modules import JAX: loaded on first use, so that ``jaxbpm convert --help`` needs none
    if name in __all__:
        return importlib.import_module(f"jaxbpm.interop.{name}")
    raise AttributeError(f"module 'jaxbpm.interop' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
