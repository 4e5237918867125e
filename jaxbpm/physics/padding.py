"""Padding a model to a size class (see :mod:`jaxbpm._compile`): extra particles and bonds that change no result, so
that samples of similar size share compiled programs.

Padding particles come after the real ones, copies of the first particle (its radius, mass, moment of inertia and
position; the second one a mean bond length further along x). Padding bonds come after the real ones and join the
first two padding particles with zero stiffness (zero area and moments of area, that length; material 0). A solver
holds the padding particles (prescribed, zero displacement) or leaves them out of its averages, and slices its outputs
back.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from jaxbpm._compile import put
from jaxbpm.physics.model import Model

__all__ = ["pad_model", "pad_rows"]


def pad_rows(a, size: int, fill=0):
    """Append rows of ``fill`` to an array.

    Args:
        a: ``[m, ...]``, NumPy or JAX.
        size: the number of rows wanted.
        fill: the value of the new rows.

    Returns:
        ``[size, ...]``, a NumPy array.

    Raises:
        ValueError: ``a`` has more than ``size`` rows.
    """
    a = np.asarray(a)
    if size < a.shape[0]:
        raise ValueError(f"cannot pad {a.shape[0]} rows to {size}")
    return np.concatenate([a, np.full((size - a.shape[0],) + a.shape[1:], fill, a.dtype)])


def pad_model(model: Model, n_cap: int, nb_cap: int) -> Model:
    """Pad a model to a size class (see the module docstring).

    Args:
        model: the model of ``n`` particles and ``nb`` bonds.
        n_cap: the particle count of the size class, at least ``n + 2``.
        nb_cap: the bond count of the size class, at least ``nb``.

    Returns:
        The model with ``n_cap - n`` padding particles and ``nb_cap - nb`` padding bonds.

    Raises:
        ValueError: the size class is too small for the model.
    """
    n, nb = model.n, int(model.bonds.shape[0])
    if n_cap < n + 2 or nb_cap < nb:
        raise ValueError(f"size class ({n_cap}, {nb_cap}) too small for {n} particles and {nb} bonds")
    dtype = model.positions0.dtype

    def grow(a, size, fill):
        return put(pad_rows(a, size, fill))

    pos0 = np.asarray(model.positions0)
    length = float(np.mean(np.asarray(model.bond_length))) if nb else float(np.asarray(model.radii)[0])
    pos = np.concatenate([pos0, np.repeat(pos0[:1], n_cap - n, 0)])
    pos[n + 1, 0] += length
    big = np.iinfo(np.asarray(model.bond_keys).dtype).max
    bonds = np.concatenate([np.asarray(model.bonds), np.repeat([[n, n + 1]], nb_cap - nb, 0)])
    r0 = np.concatenate([np.asarray(model.r0), np.repeat([pos[n + 1] - pos[n]], nb_cap - nb, 0)])

    def first(a):
        return np.asarray(a)[0]

    return dataclasses.replace(
        model, positions0=put(pos, dtype), radii=grow(model.radii, n_cap, first(model.radii)),
        mass=grow(model.mass, n_cap, first(model.mass)), inertia=grow(model.inertia, n_cap, first(model.inertia)),
        bonds=put(bonds, model.bonds.dtype), r0=put(r0, dtype),
        bond_material=grow(model.bond_material, nb_cap, 0),
        bond_area=grow(model.bond_area, nb_cap, 0.0), bond_I=grow(model.bond_I, nb_cap, 0.0),
        bond_J=grow(model.bond_J, nb_cap, 0.0), bond_length=grow(model.bond_length, nb_cap, length),
        bond_keys=grow(model.bond_keys, nb_cap, big),
        bond_key_index=put(np.concatenate([np.asarray(model.bond_key_index), np.arange(nb, nb_cap)]),
                                   model.bond_key_index.dtype),
        bond_radius=grow(model.bond_radius, nb_cap, 0.0))
