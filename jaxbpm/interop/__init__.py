"""Interoperability with other DEM codes: their bond parameter conventions (:mod:`~jaxbpm.interop.conventions`:
PFC, LAMMPS, Yade, MUSEN, translated exactly to and from jaxbpm's bond law), exchange formats
(:mod:`~jaxbpm.interop.formats`: LAMMPS data and dump files, CSV, VTU series for ParaView) and the ``jaxbpm
convert`` / ``jaxbpm params`` commands (:mod:`~jaxbpm.interop.cli`).

``jaxbpm.formats`` and ``jaxbpm.conventions`` are the old names of the two modules: they still import, with a
deprecation warning, until the next release.
"""

from jaxbpm.interop import conventions, formats

__all__ = ["conventions", "formats"]
