"""The parameters that calibrators change, a small pytree mapped onto the bonds by their material index:
``params = {"bond_E": [n_materials], "bond_nu": [n_materials]}`` and optional strengths and contact-law scalars, so
that ``grad``, ``vmap`` and optax all see one thing. :func:`default_params` gives a sample's; :func:`check_params`
is the one check every solver's ``params`` goes through.

Examples:
    >>> import jaxbpm
    >>> from jaxbpm.physics.params import check_params, default_params
    >>> sample = jaxbpm.generate.lattice("sc", (2, 2, 2), materials={"E": 2e9, "nu": 0.2})
    >>> params = default_params(sample)
    >>> sorted(params), [float(v) for v in params["bond_E"]]
    (['bond_E', 'bond_nu'], [2000000000.0])
    >>> check_params({**params, "bond_e": [1e9]}, sample)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    jaxbpm.errors.SceneError: params has an unknown key 'bond_e'; did you mean 'bond_E' or 'bond_nu'? ...
"""

from __future__ import annotations

import weakref

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm.sample import Sample

__all__ = ["default_params", "check_params"]


def default_params(sample: Sample) -> dict:
    """The calibratable parameters of a sample at their current values.

    The arrays are moved to the device once per sample and precision: a loop of solves with the defaults moves
    nothing.

    Args:
        sample: the sample.

    Returns:
        A new dict ``{"bond_E": [n_materials], "bond_nu": [n_materials]}`` of device arrays.
    """
    dtype = _float_dtype()
    key = (id(sample), dtype.name)
    hit = _DEFAULTS.get(key)
    if hit is None or hit[0]() is not sample:
        hit = (weakref.ref(sample), {"bond_E": _put(sample.materials.E, dtype),
                                     "bond_nu": _put(sample.materials.nu, dtype)})
        _DEFAULTS[key] = hit
        while len(_DEFAULTS) > 8:
            _DEFAULTS.pop(next(iter(_DEFAULTS)))
    return dict(hit[1])


_DEFAULTS: dict = {}  # (id(sample), dtype) -> (weak reference to the sample, its default parameters)


_PER_MATERIAL = {  # params keys with one entry per bond material: (check, what it must be)
    "bond_E": (lambda v: np.isfinite(v) & (v > 0), "finite and > 0 [Pa]"),
    "bond_nu": (lambda v: np.isfinite(v) & (v > -1.0) & (v < 0.5), "finite and in (-1, 0.5)"),
    "bond_tensile_strength": (lambda v: v >= 0, ">= 0 [Pa] (inf: never breaks)"),  # NaN fails it too
    "bond_shear_strength": (lambda v: v >= 0, ">= 0 [Pa] (inf: never breaks)"),
    "bond_friction_angle": (lambda v: np.isfinite(v) & (v >= 0) & (v < np.pi / 2), "finite and in [0, pi/2) [rad]"),
    "bond_moment_factor": (lambda v: np.isfinite(v) & (v >= 0) & (v <= 1), "finite and in [0, 1]"),
}
_SCALAR = {  # params keys of the contact laws (Hertz-Mindlin, linear, cohesive): scalars
    "contact_E": (lambda v: np.isfinite(v) & (v > 0), "finite and > 0 [Pa]"),
    "contact_nu": (lambda v: np.isfinite(v) & (v > -1.0) & (v < 0.5), "finite and in (-1, 0.5)"),
    "contact_emod": (lambda v: np.isfinite(v) & (v > 0), "finite and > 0 [Pa]"),
    "contact_kratio": (lambda v: np.isfinite(v) & (v > 0), "finite and > 0"),
    "friction": (lambda v: np.isfinite(v) & (v >= 0), "finite and >= 0"),
    "restitution": (lambda v: np.isfinite(v) & (v > 0) & (v <= 1), "finite and in (0, 1]"),
    "cohesion_initial": (lambda v: np.isfinite(v) & (v >= 0), "finite and >= 0 [Pa]"),
    "cohesion_from_stress": (lambda v: np.isfinite(v) & (v >= 0), "finite and >= 0"),
    "cohesion_max": (lambda v: np.isfinite(v) & (v >= 0), "finite and >= 0 [Pa]"),
}


def check_params(params, sample: Sample) -> dict:
    """Check parameters against a sample: the one validation path every solver's ``params`` goes through.

    ``bond_E`` and ``bond_nu`` are required, one entry per bond material (``[sample.n_materials]``); ``bond_E`` finite
    and > 0 [Pa], ``bond_nu`` finite and in (-1, 0.5), the range :class:`~jaxbpm.sample.BondMaterials` accepts (at -1
    the shear stiffness is infinite; at 0.5 and above the bond is not an elastic solid). Optional, per material:
    ``bond_tensile_strength`` and ``bond_shear_strength`` >= 0 [Pa] (``inf``: never breaks), ``bond_friction_angle`` in
    [0, pi/2) [rad], ``bond_moment_factor`` in [0, 1]. Optional scalars of the contact laws: ``contact_E`` > 0 [Pa],
    ``contact_nu`` in (-1, 0.5) (Hertz-Mindlin, cohesive), ``contact_emod`` > 0 [Pa] and ``contact_kratio`` > 0 (the
    linear law's E* and k_n / k_s), ``friction`` >= 0, ``restitution`` in (0, 1], ``cohesion_initial`` and
    ``cohesion_max`` >= 0 [Pa] (``cohesion_max`` >= ``cohesion_initial`` when both are given),
    ``cohesion_from_stress`` >= 0. Any other key is an error (a misspelt key would otherwise be ignored). Values must
    be real numbers (not booleans, complex numbers or strings); traced values (inside ``jit``/``grad``/``vmap``) are
    not checked.

    Args:
        params: the parameter dict.
        sample: the sample it is for.

    Returns:
        A new dict, the per-material entries as device arrays (lists, tuples and NumPy arrays are moved as they are).

    Raises:
        SceneError: a missing, unknown or out-of-range entry (the message names the key, the offending entries and
            what was expected).
    """
    import difflib
    from collections.abc import Mapping

    from jaxbpm.errors import SceneError

    if not isinstance(params, Mapping) or not {"bond_E", "bond_nu"} <= set(params):
        got = sorted(map(str, params)) if isinstance(params, Mapping) else type(params).__name__
        raise SceneError("params must be a dict with 'bond_E' and 'bond_nu', one entry per bond material (see "
                         f"jaxbpm.physics.model.default_params), got {got}")
    known = sorted(_PER_MATERIAL) + sorted(_SCALAR)
    for key in params:
        if key not in _PER_MATERIAL and key not in _SCALAR:
            close = difflib.get_close_matches(key, known, n=3, cutoff=0.6) if isinstance(key, str) else []
            hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
            raise SceneError(f"params has an unknown key {key!r}{hint} (keys: {', '.join(known)})")
    m = sample.n_materials
    out = dict(params)
    for name, (ok, what) in _PER_MATERIAL.items():
        if name not in params:
            continue
        arr = _concrete(params, name, "real numbers, one per bond material", SceneError)
        if arr is None:
            continue
        if arr.shape != (m,):
            raise SceneError(f"params[{name!r}] must have shape [{m}] (one per bond material), got shape "
                             f"{arr.shape}: {_short(arr)}")
        bad = np.flatnonzero(~ok(arr))
        if bad.size:
            raise SceneError(f"params[{name!r}] must be {what}; bad entries (material: value) "
                             + ", ".join(f"{int(k)}: {float(arr[k]):g}" for k in bad[:8]))
        if not isinstance(params[name], jax.Array):
            out[name] = _put(arr, _float_dtype())
    scalars = {}
    for name, (ok, what) in _SCALAR.items():
        if name not in params:
            continue
        arr = _concrete(params, name, "a real number", SceneError)
        if arr is not None and (arr.shape != () or not ok(arr)):
            raise SceneError(f"params[{name!r}] must be a scalar, {what}; got {_short(arr)}")
        scalars[name] = arr
    c0, c_max = scalars.get("cohesion_initial"), scalars.get("cohesion_max")
    if c0 is not None and c_max is not None and not c_max >= c0:
        raise SceneError(f"params['cohesion_max'] ({float(c_max):g} Pa) must be at least params['cohesion_initial'] "
                         f"({float(c0):g} Pa)")
    return out


def _short(arr: np.ndarray, limit: int = 8) -> str:
    """The values of ``arr`` for a message: plain numbers, the first ``limit`` of a long array."""
    flat = arr.reshape(-1).tolist()
    if arr.ndim == 0:
        return f"{flat[0]:g}"
    return str(flat[:limit])[:-1] + (f", ... ({len(flat)} values)]" if len(flat) > limit else "]")


def _concrete(params, name: str, expected: str, error):
    """``params[name]`` as a float64 NumPy array; ``None`` for a traced value (inside ``jit``/``grad``/``vmap``)."""
    value = params[name]
    if isinstance(value, jax.core.Tracer):
        return None
    try:
        arr = np.asarray(value)
        real = arr.dtype != bool and (jnp.issubdtype(arr.dtype, jnp.floating) or jnp.issubdtype(arr.dtype, jnp.integer))
        if not real:
            raise TypeError
        return np.asarray(arr, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        from jaxbpm._text import shown

        raise error(f"params[{name!r}] must be {expected}, got {shown(value)}") from None


def _float_dtype():
    """float64 with ``jax_enable_x64``, float32 without (no array is made: that would compile a program)."""
    return np.dtype(jax.dtypes.canonicalize_dtype(np.float64))


def _put(x, dtype):
    """A NumPy array (converted on the host) on the device: a transfer, never a compiled program."""
    return jax.device_put(np.asarray(x, dtype))
