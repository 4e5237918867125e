"""The base of the solvers' options classes (``jaxbpm.DEM``, ``jaxbpm.DSM``, ``jaxbpm.STE``), the value checks they
share and the registry from a solver's name to its options class.

An options class lists its options as fields, each with its default and its check (:func:`option`), and documents
them on the class (``Attributes:``). Building one checks every option: an unknown name raises
:class:`~jaxbpm.errors.OptionsError` with the closest names, a value out of range one that names the option. The
objects are frozen, hashable (arrays and callables included), comparable, picklable and print the options that
differ from the defaults:

>>> import dataclasses
>>> from jaxbpm._options import SolverOptions, option, positive
>>> class Example(SolverOptions):
...     method = "example"
...     tol: float = option(1e-3, positive, doc="relative tolerance")
>>> Example(tol=1e-6)
Example(tol=1e-06)
>>> Example(tol=1e-3) == Example(), hash(Example(tol=1e-3)) == hash(Example())
(True, True)
>>> Example(tl=1.0)
Traceback (most recent call last):
  ...
jaxbpm.errors.OptionsError: unknown EXAMPLE option 'tl'; did you mean 'tol'? (options: tol)
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import importlib
import math
import numbers
import os
from typing import Any, Callable, ClassVar

from jaxbpm._text import shown
from jaxbpm.errors import OptionsError

__all__ = ["SolverOptions", "option", "shown", "options_class", "resolve_options", "METHODS", "positive", "fraction",
           "unit_interval", "whole", "choice", "flag", "optional", "optional_path", "progress"]

#: solver name -> ``"module:class"`` of its options (imported on first use)
_REGISTRY = {"dem": "jaxbpm.dem.options:DEM", "dsm": "jaxbpm.dsm.options:DSM", "ste": "jaxbpm.ste.options:STE"}
METHODS = tuple(_REGISTRY)

Check = Callable[[str, Any], None]


# -- value checks: ``check(name, value)`` raises OptionsError naming the option, else returns None


def positive(name: str, v) -> None:
    """A finite number > 0.

    Args:
      name: the option's name (the message names it).
      v: its value.

    Raises:
      OptionsError: ``v`` is not a finite number > 0.
    """
    if isinstance(v, bool) or not isinstance(v, numbers.Real) or not (v > 0 and math.isfinite(v)):
        raise OptionsError(f"{name} must be a positive number, got {shown(v)}")


def unit_interval(lo_open: bool = True, hi_closed: bool = True) -> Check:
    """The check of a number in the unit interval.

    Args:
      lo_open: 0 excluded (``False``: allowed).
      hi_closed: 1 allowed (``False``: excluded).

    Returns:
      ``check(name, v)``, raising :class:`~jaxbpm.errors.OptionsError` for a value outside the interval.
    """
    def check(name, v):
        ok = isinstance(v, numbers.Real) and not isinstance(v, bool) and (v > 0 if lo_open else v >= 0) and (
            v <= 1 if hi_closed else v < 1)
        if not ok:
            raise OptionsError(f"{name} must lie in {'(' if lo_open else '['}0, 1{']' if hi_closed else ')'}, got "
                               f"{shown(v)}")
    return check


def fraction(name: str, v) -> None:
    """A number in ``(0, 1]``.

    Args:
      name: the option's name (the message names it).
      v: its value.

    Raises:
      OptionsError: ``v`` is not a number in (0, 1].
    """
    _FRACTION(name, v)


_FRACTION = unit_interval()


def whole(name: str, v, minimum: int = 1) -> None:
    """A whole number >= ``minimum`` (not ``True``, not ``3.0``).

    Args:
      name: the option's name (the message names it).
      v: its value.
      minimum: the least value allowed.

    Raises:
      OptionsError: ``v`` is not a whole number >= ``minimum``.
    """
    if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < minimum:
        raise OptionsError(f"{name} must be a whole number >= {minimum}, got {shown(v)}")


def _same_choice(v, a) -> bool:
    """``v`` is the choice ``a``: ``None`` is ``None``, a string that string, a number that whole number (not
    ``True``, ``3.0`` or an array)."""
    if a is None:
        return v is None
    if isinstance(a, str):
        return isinstance(v, str) and v == a
    return isinstance(v, numbers.Integral) and not isinstance(v, bool) and int(v) == a


def choice(*allowed) -> Check:
    """The check of one of a few values.

    Args:
      *allowed: the values (``None``, strings or whole numbers).

    Returns:
      ``check(name, v)``, raising :class:`~jaxbpm.errors.OptionsError` for any other value.
    """
    def check(name, v):
        if not any(_same_choice(v, a) for a in allowed):
            names = [repr(a) for a in allowed]
            choices = " or ".join(names) if len(names) == 2 else "one of " + ", ".join(names)
            raise OptionsError(f"{name} must be {choices}, got {shown(v)}")
    return check


def flag(name: str, v) -> None:
    """``True`` or ``False`` (not 1, not NumPy booleans).

    Args:
      name: the option's name (the message names it).
      v: its value.

    Raises:
      OptionsError: ``v`` is not a bool.
    """
    if not isinstance(v, bool):
        raise OptionsError(f"{name} must be True or False, got {shown(v)}")


def optional(check: Check) -> Check:
    """A check that lets ``None`` through (the solver's own default).

    Args:
      check: the check of the other values.

    Returns:
      ``check(name, v)`` for values other than ``None``.
    """
    def optional_check(name, v):
        if v is not None:
            check(name, v)
    return optional_check


def optional_path(name: str, v) -> None:
    """A file path (``str`` or ``os.PathLike``) or ``None``.

    Args:
      name: the option's name (the message names it).
      v: its value.

    Raises:
      OptionsError: ``v`` is neither.
    """
    if v is not None and not isinstance(v, (str, os.PathLike)):
        raise OptionsError(f"{name} must be a file path (a str or pathlib.Path) or None, got {shown(v)}")


def progress(name: str, v) -> None:
    """``True``, ``False``, ``None`` or a callable ``progress(steps_done, steps_total, elapsed_s)``.

    Args:
      name: the option's name (the message names it).
      v: its value.

    Raises:
      OptionsError: ``v`` is none of these.
    """
    if v is not None and not isinstance(v, bool) and not callable(v):
        raise OptionsError(f"{name} must be True, False (or None) or a callable progress(steps_done, steps_total, "
                           f"elapsed_s), got {shown(v)}")


# -- the base class


def option(default=None, check: Check | None = None, *, doc: str = ""):
    """A field of a :class:`SolverOptions` class.

    Args:
      default: the option's default (immutable: a number, a string, ``None``, a bool).
      check: ``check(name, value)``, run when an object is built (``None``: any value).
      doc: a one-line description (the class's ``Attributes:`` section documents the option).

    Returns:
      The ``dataclasses.field``.
    """
    return dataclasses.field(default=default, metadata={"check": check, "doc": doc})


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


def _check_names(cls, given) -> None:
    names = cls.names()
    for name in given:
        if name not in names:
            close = difflib.get_close_matches(name, names, n=3, cutoff=0.6) if isinstance(name, str) else []
            hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
            raise OptionsError(f"unknown {cls.method.upper()} option {name!r}{hint} (options: {', '.join(names)})")


class SolverOptions:
    """Options of one solver: fields with defaults, checked when built, immutable and hashable.

    A subclass sets ``method`` (the solver's name) and declares its options with :func:`option`; it becomes a frozen,
    keyword-only dataclass (no decorator needed). Use :class:`jaxbpm.DEM`, :class:`jaxbpm.DSM` or
    :class:`jaxbpm.STE`.

    Attributes:
      method: the solver's name (a class variable).

    Raises:
      OptionsError: an unknown option (with the closest names) or a value out of its range (naming the option).
    """

    method: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        dataclasses.dataclass(cls, frozen=True, kw_only=True, eq=False, repr=False)
        generated = cls.__init__

        @functools.wraps(generated)
        def __init__(self, **options):
            options = type(self)._renamed(options)
            _check_names(type(self), options)
            generated(self, **options)

        cls.__init__ = __init__

    def __post_init__(self):
        for f in dataclasses.fields(self):
            check = f.metadata.get("check")
            if check is not None:
                check(f.name, getattr(self, f.name))

    @classmethod
    def _renamed(cls, options: dict) -> dict:
        """The options given, with deprecated names mapped onto the options they became (a subclass that renamed an
        option overrides this and warns with :class:`DeprecationWarning`)."""
        return options

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The option names, sorted."""
        return tuple(sorted(f.name for f in dataclasses.fields(cls)))

    @classmethod
    def defaults(cls) -> dict:
        """Every option's default."""
        return {f.name: f.default for f in dataclasses.fields(cls)}

    def asdict(self) -> dict:
        """Every option and its value (the values themselves, not copies)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def changed(self) -> dict:
        """The options whose values differ from the defaults."""
        defaults = self.defaults()
        return {k: v for k, v in self.asdict().items() if _frozen(v) != _frozen(defaults[k])}

    def replace(self, **changes) -> SolverOptions:
        """A copy with some options changed (checked like a new one)."""
        return type(self)(**{**self.asdict(), **changes})

    def __eq__(self, other):
        return type(other) is type(self) and _frozen(self.asdict()) == _frozen(other.asdict())

    def __hash__(self):
        return hash((type(self).__name__, self.method, _frozen(self.asdict())))

    def __repr__(self):
        return f"{type(self).__name__}({', '.join(f'{k}={v!r}' for k, v in self.changed().items())})"


def options_class(method: str) -> type[SolverOptions]:
    """The options class of a solver, imported on first use.

    Args:
      method: ``"dem"``, ``"dsm"`` or ``"ste"``.

    Returns:
      Its :class:`SolverOptions` subclass.

    Raises:
      OptionsError: an unknown solver name.
    """
    if not isinstance(method, str) or method not in _REGISTRY:
        raise OptionsError(f"unknown method {shown(method)}; choose one of {METHODS}")
    return _load(method)


@functools.lru_cache(maxsize=None)
def _load(method: str) -> type[SolverOptions]:
    module, _, name = _REGISTRY[method].partition(":")
    return getattr(importlib.import_module(module), name)


def resolve_options(method, options: dict) -> SolverOptions:
    """The options object of a solve: from a solver name (``"dsm"``) or an options object, with keyword ``options``
    overriding its values, checked.

    Args:
      method: a solver's name or a :class:`SolverOptions`.
      options: option names and values.

    Returns:
      The options object.

    Raises:
      OptionsError: an unknown solver, an unknown option or a value out of range.
    """
    if isinstance(method, SolverOptions):
        return method.replace(**options) if options else method
    if not isinstance(method, str) or method not in _REGISTRY:
        raise OptionsError(f"unknown method {shown(method)}; choose one of {METHODS} or pass jaxbpm.DEM(...), "
                           "jaxbpm.DSM(...) or jaxbpm.STE(...)")
    return options_class(method)(**options)
