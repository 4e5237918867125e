"""The tables the ``jaxbpm convert`` and ``jaxbpm params`` commands show in their help: file suffixes and named
readers (:mod:`jaxbpm.interop.formats`), bond parameter conventions (:mod:`jaxbpm.interop.conventions`). Kept
apart from those modules (which import JAX) so that ``--help`` answers without it."""

from __future__ import annotations

from typing import Any

import numpy as np

FORMATS = {".h5": "jaxbpm HDF5 sample", ".hdf5": "jaxbpm HDF5 sample", ".data": "LAMMPS data file",
           ".lmp": "LAMMPS data file", ".csv": "CSV particles + <stem>_bonds.csv",
           ".vtu": "VTK XML (write only)", ".vtk": "legacy VTK (write only)",
           ".pvd": "VTU time series from a LAMMPS dump (write only, needs a sample)",
           ".vtkhdf": "VTKHDF time series, topology stored once (write only, from a LAMMPS dump, needs a sample)",
           ".dump": "LAMMPS text dump (read only, to .pvd or .vtkhdf)",
           ".lammpstrj": "LAMMPS text dump (read only, to .pvd or .vtkhdf)"}

# formats read when named (format=..., --format), whatever the suffix
READERS = {"hdf5": "jaxbpm HDF5 sample", "lammps": "LAMMPS data file", "csv": "CSV particles + <stem>_bonds.csv",
           "liggghts": "LIGGGHTS data file (atom_style granular)",
           "yade": "Yade export.textExt sphere list (x_y_z_r, x_y_z_r_matId, x_y_z_r_attrs; bonds at contacts)"}

# name -> (parameter names with defaults (None = required), needs (length, radius1, radius2)?)
CONVENTIONS: dict[str, dict[str, Any]] = {
    "jaxbpm": {"params": {"E": None, "nu": None, "bond_radius": None, "bond_radius_ratio": None,
                          "tensile_strength": np.inf, "shear_strength": np.inf},
               "doc": "E [Pa], nu, bond_radius [m] (or bond_radius_ratio = r_b / min(R1, R2)), tensile_strength, "
                      "shear_strength [Pa]"},
    "pfc": {"params": {"pb_kn": None, "pb_ks": None, "emod": None, "kratio": None, "pb_rmul": 1.0,
                       "pb_ten": np.inf, "pb_coh": np.inf, "pb_fa": 0.0, "pb_mcf": 1.0},
            "doc": "pb_kn, pb_ks [Pa/m] or emod [Pa], kratio; pb_rmul; pb_ten, pb_coh [Pa]; pb_fa [deg]; pb_mcf"},
    "lammps": {"params": {"Kr": None, "Ks": None, "Kt": None, "Kb": None, "Fcr": np.inf, "Fcs": np.inf,
                          "Tct": np.inf, "Tcb": np.inf, "normalize": 0.0},
               "doc": "Kr, Ks [N/m] (normalize=1: [N]), Kt, Kb [N m/rad]; Fcr, Fcs [N]; Tct, Tcb [N m]"},
    "yade": {"params": {"young": None, "poisson": None, "alphaKr": None, "alphaKtw": None,
                        "normalCohesion": np.inf, "shearCohesion": np.inf, "rollingCohesion": None,
                        "twistingCohesion": None},
             "doc": "young [Pa], poisson (= ks/kn), alphaKr, alphaKtw; normalCohesion, shearCohesion, "
                    "rollingCohesion, twistingCohesion [Pa]"},
    "musen": {"params": {"diameter": None, "young_modulus": None, "poisson_ratio": None,
                         "normal_strength": np.inf, "tangential_strength": np.inf},
              "doc": "diameter [m], young_modulus [Pa], poisson_ratio; normal_strength, tangential_strength [Pa]"},
}
