"""Solver options as frozen, hashable objects: ``jaxbpm.DEM(...)``, ``jaxbpm.DSM(...)``, ``jaxbpm.STE(...)``.

``jaxbpm.solve(sample, scene, jaxbpm.DSM(dofs=3, stiffness_tol=1e-3))`` is the same solve as
``jaxbpm.solve(sample, scene, method="dsm", dofs=3, stiffness_tol=1e-3)``; the object form checks every option when
it is built (an unknown name gets a "did you mean", a value out of range names the range), can be kept, compared,
hashed and passed around (a calibrator, a sweep, a benchmark table), and prints as it was written. Options left out
keep the solver's defaults (see :func:`jaxbpm.solve`).
"""

from __future__ import annotations

import difflib
import functools
import inspect
import math
import numbers
import os
from typing import Any, ClassVar

from jaxbpm.errors import SceneError

__all__ = ["SolverOptions", "DEM", "DSM", "STE", "options_for"]


def _shown(v) -> str:
    """``v`` for a message: plain numbers (``0.5``, not ``np.float64(0.5)``), shortened."""
    from jaxbpm.sample import _shown as shown

    return shown(v)


def _positive(name, v):
    if isinstance(v, bool) or not isinstance(v, numbers.Real) or not (v > 0 and math.isfinite(v)):
        raise SceneError(f"{name} must be a positive number, got {_shown(v)}")


def _optional_positive(name, v):
    if v is not None:
        _positive(name, v)


def _fraction(name, v, lo_open=True, hi_closed=True):
    ok = isinstance(v, numbers.Real) and not isinstance(v, bool) and (v > 0 if lo_open else v >= 0) and (
        v <= 1 if hi_closed else v < 1)
    if not ok:
        raise SceneError(f"{name} must lie in {'(' if lo_open else '['}0, 1{']' if hi_closed else ')'}, got "
                         f"{_shown(v)}")


def _whole(name, v, minimum=1):
    if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < minimum:
        raise SceneError(f"{name} must be a whole number >= {minimum}, got {_shown(v)}")


def _optional_whole(name, v, minimum=1):
    if v is not None:
        _whole(name, v, minimum)


def _same_choice(v, a) -> bool:
    """``v`` is the choice ``a``: ``None`` is ``None``, a string that string, a number that whole number (not
    ``True``, ``3.0`` or an array)."""
    if a is None:
        return v is None
    if isinstance(a, str):
        return isinstance(v, str) and v == a
    return isinstance(v, numbers.Integral) and not isinstance(v, bool) and int(v) == a


def _choice(*allowed):
    def check(name, v):
        if not any(_same_choice(v, a) for a in allowed):
            names = [repr(a) for a in allowed]
            choices = " or ".join(names) if len(names) == 2 else "one of " + ", ".join(names)
            raise SceneError(f"{name} must be {choices}, got {_shown(v)}")
    return check


def _flag(name, v):
    if not isinstance(v, bool):
        raise SceneError(f"{name} must be True or False, got {_shown(v)}")


def _optional_path(name, v):
    if v is not None and not isinstance(v, (str, os.PathLike)):
        raise SceneError(f"{name} must be a file path (a str or pathlib.Path) or None, got {_shown(v)}")


def _progress(name, v):
    if v is not None and not isinstance(v, bool) and not callable(v):
        raise SceneError(f"{name} must be True, False (or None) or a callable progress(steps_done, steps_total, "
                         f"elapsed_s), got {_shown(v)}")


def _neighbors(name, v):
    from jaxbpm.dem.neighbors import NeighborSettings

    if v is not None and not isinstance(v, NeighborSettings):
        raise SceneError(f"{name} must be a jaxbpm.dem.NeighborSettings or None, got {_shown(v)}")


def _surface_depth(name, v):
    if v is None or (isinstance(v, numbers.Real) and not isinstance(v, bool) and v == 0):
        return
    _positive(name, v)


def _volumes(name, v):
    if v is None:
        return
    import numpy as np

    try:
        arr = np.asarray(v)
        ok = arr.dtype != bool and (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer))
        ok = ok and arr.ndim == 1 and bool(np.all(np.isfinite(arr) & (arr > 0)))
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise SceneError(f"{name} must be [n] finite positive particle volumes [m^3], got {_shown(v)}")


def _optional_flag(name, v):
    if v is not None:
        _flag(name, v)


# value checks per option (every option has one; the solver checks what needs the sample, e.g. the length of
# volumes)
_CHECKS = {
    "dem": {"dt": _optional_positive, "safety": _fraction, "damping": lambda n, v: _fraction(n, v, False, False),
            "loading_time": _optional_positive, "transits": _positive, "chunk": _optional_whole,
            "max_records": _whole, "snapshots": _optional_whole, "pad": _flag, "throw": _flag,
            "overwrite": _flag, "progress": _progress, "neighbors": _neighbors, "record_to": _optional_path,
            "vtu": _optional_path, "resume": _optional_path},
    "dsm": {"dofs": _choice(None, 3, 6), "nonlinear": _optional_flag, "tol": _optional_positive,
            "linear_tol": _positive, "maxiter": _optional_whole, "newton_maxiter": _whole,
            "stiffness_tol": lambda n, v: None if isinstance(v, str) and v == "auto" else _optional_positive(n, v),
            "contact_skin": _optional_positive, "load_steps": _whole,
            "throw": _flag, "operator": _choice("auto", "jacobians", "jvp"),
            "preconditioner": _choice("auto", "two-level", "jacobi"), "aggregate_size": _optional_positive,
            "slip": _flag, "contact_fraction": lambda n, v: None if v is None else _fraction(n, v),
            "contact_passes": _whole, "pad": _flag, "geometric_correction": _flag},
    "ste": {"dofs": _choice(3, 6), "first_neighbour": _flag, "layered": _flag, "contacts": _optional_flag,
            "contact_fraction": lambda n, v: None if v is None else _fraction(n, v),
            "layer_thickness": _optional_positive, "surface_depth": _surface_depth, "volumes": _volumes,
            "precision": _choice("float64", "float32"), "pad": _flag, "throw": _flag, "clamp_layers": _flag},
}


@functools.lru_cache(maxsize=None)
def accepted(method: str) -> tuple[str, ...]:
    """The option names ``method`` takes (from the solver's own signature: one list, no copy to keep in step)."""
    if method == "dem":
        from jaxbpm.dem.scene import solve_scene as fn
    elif method == "dsm":
        from jaxbpm.dsm import solve_scene as fn
    elif method == "ste":
        from jaxbpm import ste

        names = set(inspect.signature(ste.solve_scene).parameters) | set(inspect.signature(ste.estimator).parameters)
        return tuple(sorted(names - {"sample", "scene", "params", "options", "self"}))
    else:
        raise SceneError(f"unknown method {_shown(method)}; choose one of {tuple(_CHECKS)}")
    names = [p.name for p in inspect.signature(fn).parameters.values()
             if p.kind == p.KEYWORD_ONLY and not p.name.startswith("_")]
    return tuple(sorted(names))


def check_options(method: str, options: dict) -> None:
    """Raise :class:`~jaxbpm.errors.SceneError` for an option ``method`` does not take (with the closest names) or
    a value out of its range."""
    names = accepted(method)
    for name, value in options.items():
        if name not in names:
            close = difflib.get_close_matches(name, names, n=3, cutoff=0.6) if isinstance(name, str) else []
            hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
            raise SceneError(f"unknown {method.upper()} option {name!r}{hint} (options: {', '.join(names)})")
        check = _CHECKS[method].get(name)
        if check is not None:
            check(name, value)


def _frozen(value):
    """A hashable stand-in for ``value`` (lists and arrays as tuples), for hashing and comparing option objects."""
    if isinstance(value, dict):
        return tuple(sorted((k, _frozen(v)) for k, v in value.items()))
    if isinstance(value, (list, tuple)):
        return tuple(_frozen(v) for v in value)
    if hasattr(value, "tolist") and hasattr(value, "shape"):
        return ("array", tuple(value.shape), _frozen(value.tolist()))
    try:
        hash(value)
    except TypeError:
        return ("object", id(value))
    return value


class SolverOptions:
    """Options of one solver, checked when built, immutable and hashable. Use :class:`DEM`, :class:`DSM` or
    :class:`STE`."""

    method: ClassVar[str] = ""
    __slots__ = ("_options",)

    def __init__(self, **options: Any):
        check_options(self.method, options)
        object.__setattr__(self, "_options", dict(sorted(options.items())))

    def __setattr__(self, name, value):
        raise AttributeError(f"{type(self).__name__} options are immutable; use .replace({name}=...)")

    def __getattr__(self, name):
        options = object.__getattribute__(self, "_options")
        if name in options:
            return options[name]
        if name in accepted(self.method):
            return None  # left to the solver's default
        raise AttributeError(f"{type(self).__name__} has no option {name!r}")

    def asdict(self) -> dict:
        """The options given (the solver's defaults for the rest)."""
        return dict(self._options)

    def replace(self, **changes) -> "SolverOptions":
        """A copy with some options changed (checked like a new one)."""
        return type(self)(**{**self._options, **changes})

    def __eq__(self, other):
        return type(other) is type(self) and _frozen(self._options) == _frozen(other._options)

    def __hash__(self):
        return hash((self.method, _frozen(self._options)))

    def __repr__(self):
        return f"{type(self).__name__}({', '.join(f'{k}={v!r}' for k, v in self._options.items())})"

    def __reduce__(self):
        return (_rebuild, (type(self), self._options))


def _rebuild(cls, options):
    return cls(**options)


class DEM(SolverOptions):
    """Explicit DEM options (``dt``, ``safety``, ``damping``, ``loading_time``, ``transits``, ``chunk``,
    ``progress``, ``neighbors``, ``max_records``, ``record_to``, ``snapshots``, ``vtu``, ``pad``); see
    :func:`jaxbpm.solve`."""

    method = "dem"
    __slots__ = ()


class DSM(SolverOptions):
    """Direct stiffness method options (``dofs``, ``nonlinear``, ``tol``, ``linear_tol``, ``maxiter``,
    ``stiffness_tol``, ``operator``, ``preconditioner``, ``contact_skin``, ``load_steps``, ``slip``, ``throw``,
    ``pad``, ...); see :func:`jaxbpm.solve`."""

    method = "dsm"
    __slots__ = ()


class STE(SolverOptions):
    """Stiffness tensor estimation options (``dofs``, ``first_neighbour``, ``layered``, ``layer_thickness``,
    ``contact_fraction``, ``surface_depth``, ``volumes``, ``precision``, ``pad``, ``clamp_layers``); see
    :func:`jaxbpm.solve`."""

    method = "ste"
    __slots__ = ()


_CLASSES = {"dem": DEM, "dsm": DSM, "ste": STE}


def options_for(method, options: dict) -> tuple[str, dict]:
    """``(method name, options)`` from a method string or a :class:`SolverOptions` and keyword options (keywords
    override the object's), checked."""
    if isinstance(method, SolverOptions):
        merged = {**method.asdict(), **options}
        name = method.method
    elif isinstance(method, str) and method in _CLASSES:
        merged, name = dict(options), method
    else:
        raise SceneError(f"unknown method {_shown(method)}; choose one of {tuple(_CLASSES)} or pass jaxbpm.DEM(...), "
                         "jaxbpm.DSM(...) or jaxbpm.STE(...)")
    check_options(name, merged)
    return name, merged
