"""What a calibration aims at and what it changes: :class:`Target` (one measured quantity of a scene, its weight and
the scale of its error) and :class:`Parameter` / :class:`ParameterSpace` (the free entries of the parameter pytree
with bounds, mapped to an optimisation variable in log or target-scaled form). See :mod:`jaxbpm.calibrate.objective`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm.errors import JaxbpmError

__all__ = ["CalibrationError", "Target", "Parameter", "ParameterSpace", "ELASTIC_OBSERVABLES", "as_targets"]

ELASTIC_OBSERVABLES = ("stiffness", "youngs_modulus")
"""Observables that are homogeneous of degree one in the bond Young's moduli of a bonds-only linear scene."""

_SOLVER_OBSERVABLES = ("stiffness", "youngs_modulus", "poisson_ratio", "stress")
DEFAULT_SCENE = "main"


class CalibrationError(JaxbpmError, ValueError):
    """A calibration is ill-posed (bad targets, parameters or options) or cannot proceed."""


def _finite_array(name: str, value) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise CalibrationError(f"{name} must be a number or a list of numbers, got {value!r}") from None
    if arr.ndim > 1 or arr.size == 0:
        raise CalibrationError(f"{name} must be a number or a 1-D list of numbers, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise CalibrationError(f"{name} must be finite, got {arr.tolist()}")
    return arr


# ---------------------------------------------------------------------------------------------------- targets
@dataclasses.dataclass(frozen=True)
class Target:
    """A calibration target.

    observable: ``"stiffness"`` [N/m], ``"youngs_modulus"`` [Pa], ``"poisson_ratio"`` (when the model reports one),
      ``"stress"`` (the stress-strain curve sampled at the strains ``at``, [Pa]) or any key a custom model returns.
    value: the measured value (a number, or one number per point of ``at`` / element of a vector observable).
    weight: relative weight (> 0); a :class:`Problem` normalises the weights to sum 1 (Qu et al. 2020, Eq. 3).
    scene: key of the scene it is measured on (when a model has several scenes, e.g. ``{"ucs": ..., "tpb": ...}``).
    at: strains at which a ``"stress"`` target samples the curve.
    scale: error normaliser ``s`` (relative error ``(y - t) / s``); default ``|t|`` (scalar) or ``max |t|`` (vector).
    name: label in tables and histories; default the observable (prefixed by the scene unless it is the default).
    """

    observable: str
    value: Any
    weight: float = 1.0
    scene: str = DEFAULT_SCENE
    at: Any = None
    scale: float | None = None
    name: str | None = None

    def __post_init__(self):
        if not isinstance(self.observable, str) or not self.observable:
            raise CalibrationError(f"target observable must be a non-empty string, got {self.observable!r}")
        value = _finite_array(f"target {self.observable!r} value", self.value)
        object.__setattr__(self, "value", value if value.ndim else float(value))
        if not (isinstance(self.weight, (int, float, np.number)) and np.isfinite(self.weight) and self.weight > 0):
            raise CalibrationError(f"target {self.observable!r}: weight must be a finite number > 0, "
                                   f"got {self.weight!r}")
        if self.observable == "stress":
            if self.at is None:
                raise CalibrationError("a 'stress' target needs 'at': the strains of its curve points")
            at = _finite_array("target 'stress' at", self.at).reshape(-1)
            if at.size != np.size(value):
                raise CalibrationError(f"target 'stress': {at.size} strains in 'at' but {np.size(value)} values")
            object.__setattr__(self, "at", tuple(float(a) for a in at))
        elif self.at is not None:
            raise CalibrationError(f"'at' applies to 'stress' targets only, not {self.observable!r}")
        if self.observable in ("stiffness", "youngs_modulus") and np.any(value <= 0):
            raise CalibrationError(f"target {self.observable!r} must be > 0, got {value.tolist()}")
        scale = self.scale if self.scale is not None else float(np.max(np.abs(value)))
        if not (np.isfinite(scale) and scale > 0):
            raise CalibrationError(f"target {self.observable!r}: the error scale must be > 0 (a target of zero "
                                   "needs an explicit 'scale')")
        object.__setattr__(self, "scale", float(scale))
        if self.name is None:
            label = self.observable if self.scene == DEFAULT_SCENE else f"{self.scene}.{self.observable}"
            object.__setattr__(self, "name", label)

    @property
    def size(self) -> int:
        return int(np.size(self.value))

    @property
    def elastic(self) -> bool:
        return self.observable in ELASTIC_OBSERVABLES

    def extract(self, observations: Mapping[str, Mapping[str, Any]]):
        """This target's value from a forward's observations.

        Args:
          observations: ``{scene: {observable: value}}`` (NumPy or JAX arrays).

        Returns:
          ``[size]`` (a stress target: the curve interpolated at ``at``).

        Raises:
          CalibrationError: the observations lack the target's scene or observable.
        """
        try:
            obs = observations[self.scene]
        except KeyError:
            raise CalibrationError(f"target {self.name!r}: the model has no scene {self.scene!r} "
                                   f"(scenes: {sorted(observations)})") from None
        xp = jnp if any(isinstance(v, jax.Array) for v in obs.values()) else np
        if self.observable == "stress":
            if "strain" not in obs or "stress" not in obs:
                raise CalibrationError(f"target {self.name!r}: the model gives no stress-strain curve")
            return xp.interp(xp.asarray(self.at), obs["strain"], obs["stress"])
        if self.observable not in obs:
            raise CalibrationError(f"target {self.name!r}: the model does not report {self.observable!r} "
                                   f"(it reports {sorted(obs)})")
        return xp.reshape(xp.asarray(obs[self.observable], dtype=xp.float64), (-1,))

    def relative_error(self, y):
        """The relative error of a forward's value.

        Args:
          y: the value ``[size]`` (NumPy or JAX).

        Returns:
          ``(y - t) / s`` per element.
        """
        xp = jnp if isinstance(y, jax.Array) else np
        return (y - xp.reshape(xp.asarray(self.value), (-1,))) / self.scale


def as_targets(targets) -> list[Target]:
    """Targets from the forms the calibrators accept.

    Args:
      targets: a :class:`Target`, a list of them, or a mapping ``{observable: value}``.

    Returns:
      A list of :class:`Target`.

    Raises:
      CalibrationError: anything else, or an empty list.
    """
    if isinstance(targets, Target):
        return [targets]
    if isinstance(targets, Mapping):
        return [Target(k, v) for k, v in targets.items()]
    if isinstance(targets, (list, tuple)) and targets and all(isinstance(t, Target) for t in targets):
        return list(targets)
    raise CalibrationError("targets must be a Target, a non-empty list of Targets or a mapping "
                           f"{{observable: value}}, got {targets!r}")


# ---------------------------------------------------------------------------------------------------- parameters
@dataclasses.dataclass(frozen=True)
class Parameter:
    """One free parameter: an entry of the parameter pytree.

    key: the pytree entry (``"bond_E"``, ``"bond_nu"``, ...).
    index: the material component; ``None`` = one value for every component, multiplied by ``ratio``
      (e.g. ``ratio=(1, 4)``: two components whose moduli keep the ratio 1:4; the value is that of ratio 1).
    bounds: ``(lo, hi)``; default ``(initial / 100, initial * 100)`` for positive parameters.
    initial: starting value; default the sample's current value.
    scale: scale of the target-scaled form (Qu et al. 2020, Eq. 10); default the value of the target it is tied to,
      else its initial value.
    """

    key: str = "bond_E"
    index: int | None = None
    bounds: tuple[float, float] | None = None
    initial: float | None = None
    ratio: tuple[float, ...] | None = None
    scale: float | None = None
    name: str | None = None

    def __post_init__(self):
        if self.name is None:
            object.__setattr__(self, "name", self.key if self.index is None else f"{self.key}[{self.index}]")
        if self.index is not None and self.ratio is not None:
            raise CalibrationError(f"parameter {self.name!r}: 'ratio' applies to index=None only")
        if self.ratio is not None:
            r = _finite_array(f"parameter {self.name!r} ratio", self.ratio).reshape(-1)
            if np.any(r <= 0):
                raise CalibrationError(f"parameter {self.name!r}: ratio must be > 0, got {r.tolist()}")
            object.__setattr__(self, "ratio", tuple(float(v) for v in r))
        if self.bounds is not None:
            b = _finite_array(f"parameter {self.name!r} bounds", self.bounds)
            if b.shape != (2,) or not b[0] < b[1]:
                raise CalibrationError(f"parameter {self.name!r}: bounds must be (lo, hi) with lo < hi, "
                                       f"got {self.bounds!r}")
            object.__setattr__(self, "bounds", (float(b[0]), float(b[1])))
        for what in ("initial", "scale"):
            v = getattr(self, what)
            if v is not None and not (isinstance(v, (int, float, np.number)) and np.isfinite(v)):
                raise CalibrationError(f"parameter {self.name!r}: {what} must be a finite number, got {v!r}")
        if self.scale is not None and self.scale <= 0:
            raise CalibrationError(f"parameter {self.name!r}: scale must be > 0, got {self.scale!r}")


class ParameterSpace:
    """Free parameters on top of a base pytree; maps values ``v [n]`` to full parameter pytrees.

    scaling: ``"log"`` (``z = log(v / v0)``, v0 the initial values; positive parameters only) or ``"target"``
    (``z = v / scale``, Qu et al. 2020 Eq. 10-11). ``to_params`` is traceable (``grad``/``vmap``).
    """

    def __init__(self, parameters: Sequence[Parameter], base: Mapping[str, Any], *, scaling: str = "log",
                 scales: Sequence[float] | None = None):
        parameters = list(parameters)
        if not parameters or not all(isinstance(p, Parameter) for p in parameters):
            raise CalibrationError("parameters must be a non-empty list of Parameter")
        if scaling not in ("log", "target"):
            raise CalibrationError(f"scaling must be 'log' or 'target', got {scaling!r}")
        self.base = {k: jnp.asarray(v) for k, v in base.items()}
        seen = {}
        names = [p.name for p in parameters]
        if len(set(names)) != len(names):
            raise CalibrationError(f"parameter names must be unique, got {names}")
        for p in parameters:
            if p.key not in self.base:
                raise CalibrationError(f"parameter {p.name!r}: no entry {p.key!r} in the parameter pytree "
                                       f"(entries: {sorted(self.base)})")
            n_comp = int(np.size(self.base[p.key]))
            comps = range(n_comp) if p.index is None else [p.index]
            if p.index is not None and not (0 <= p.index < n_comp):
                raise CalibrationError(f"parameter {p.name!r}: index {p.index} out of range "
                                       f"({p.key} has {n_comp} components)")
            if p.ratio is not None and len(p.ratio) != n_comp:
                raise CalibrationError(f"parameter {p.name!r}: ratio has {len(p.ratio)} entries, {p.key} has "
                                       f"{n_comp} components")
            for c in comps:
                if (p.key, c) in seen:
                    raise CalibrationError(f"parameters {seen[(p.key, c)]!r} and {p.name!r} both set "
                                           f"{p.key}[{c}]")
                seen[(p.key, c)] = p.name
        self.parameters = parameters
        self.scaling = scaling
        init, lo, hi = [], [], []
        for p in parameters:
            base_v = np.asarray(self.base[p.key], dtype=np.float64).reshape(-1)
            v0 = p.initial if p.initial is not None else (
                float(base_v[p.index]) if p.index is not None else float(base_v[0] / (p.ratio or (1.0,))[0]))
            if p.bounds is not None:
                b = p.bounds
            elif v0 > 0:
                b = (v0 / 100.0, v0 * 100.0)
            else:
                raise CalibrationError(f"parameter {p.name!r}: give bounds (its initial value {v0!r} is not > 0)")
            if not b[0] <= v0 <= b[1]:
                raise CalibrationError(f"parameter {p.name!r}: initial value {v0:.6g} outside its bounds {b}")
            if scaling == "log" and b[0] <= 0:
                raise CalibrationError(f"parameter {p.name!r}: the log form needs positive bounds, got {b}")
            init.append(v0)
            lo.append(b[0])
            hi.append(b[1])
        self.initial = np.asarray(init)
        self.lower, self.upper = np.asarray(lo), np.asarray(hi)
        if scales is None:
            scales = [p.scale if p.scale is not None else v for p, v in zip(parameters, init)]
        self.scales = np.asarray(scales, dtype=np.float64)
        if self.scales.shape != (len(parameters),) or np.any(~(self.scales > 0)):
            raise CalibrationError(f"scales must be {len(parameters)} numbers > 0, got {scales!r}")

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    @property
    def n(self) -> int:
        return len(self.parameters)

    def with_scales(self, scales) -> "ParameterSpace":
        """This space with other scales of the target-scaled form.

        Args:
          scales: ``[n]`` numbers > 0.

        Returns:
          A new :class:`ParameterSpace`.
        """
        return ParameterSpace(self.parameters, self.base, scaling=self.scaling, scales=scales)

    def with_initial(self, values) -> "ParameterSpace":
        """This space starting from other values.

        Args:
          values: ``[n]``, clipped to the bounds.

        Returns:
          A new :class:`ParameterSpace`.
        """
        values = self.clip(values)
        params = [dataclasses.replace(p, initial=float(v)) for p, v in zip(self.parameters, values)]
        return ParameterSpace(params, self.base, scaling=self.scaling, scales=self.scales)

    def subspace(self, names: Sequence[str], fixed_values) -> "ParameterSpace":
        """The space of some parameters only, the others fixed.

        Args:
          names: the parameters kept.
          fixed_values: all ``n`` values; those of the parameters left out are written into the base pytree.

        Returns:
          A new :class:`ParameterSpace`.
        """
        base = self.to_params(np.asarray(fixed_values, dtype=np.float64))
        keep = [i for i, p in enumerate(self.parameters) if p.name in names]
        params = [dataclasses.replace(self.parameters[i], initial=float(np.clip(fixed_values[i], self.lower[i],
                                                                                self.upper[i])))
                  for i in keep]
        return ParameterSpace(params, base, scaling=self.scaling, scales=self.scales[keep])

    def clip(self, values) -> np.ndarray:
        """Values clipped to the bounds.

        Args:
          values: ``[..., n]``.

        Returns:
          The clipped values (NumPy).
        """
        return np.clip(np.asarray(values, dtype=np.float64), self.lower, self.upper)

    # the optimisation variable z
    def to_z(self, values):
        """The optimisation variable of parameter values.

        Args:
          values: ``[..., n]`` (NumPy or JAX).

        Returns:
          ``z = log(v / v0)`` in log form, ``z = v / scale`` in target-scaled form.
        """
        xp = jnp if isinstance(values, jax.Array) else np
        if self.scaling == "log":
            return xp.log(values / self.initial)
        return values / self.scales

    def from_z(self, z, initial=None, scales=None):
        """Parameter values of the optimisation variable (the inverse of :meth:`to_z`).

        Args:
          z: ``[..., n]`` (NumPy or JAX).
          initial, scales: override the space's own (traced arguments of a compiled loss).

        Returns:
          The values ``[..., n]``.
        """
        xp = jnp if isinstance(z, jax.Array) else np
        if self.scaling == "log":
            return (self.initial if initial is None else initial) * xp.exp(z)
        return z * (self.scales if scales is None else scales)

    @property
    def structure(self) -> tuple:
        """What the mapping ``values -> params`` depends on besides the base values (a compilation key)."""
        return tuple((p.key, p.index, p.ratio) for p in self.parameters) + (self.scaling,)

    def to_params(self, values, base=None) -> dict:
        """The full parameter pytree for parameter values (traceable).

        Args:
          values: ``[n]``.
          base: overrides the base pytree.

        Returns:
          ``{entry: array}``: the base with the free entries set (a common value times ``ratio`` where ``index`` is
          None).
        """
        out = dict(self.base if base is None else base)
        for i, p in enumerate(self.parameters):
            v = values[i]
            arr = jnp.asarray(out[p.key])
            if p.index is None:
                ratio = jnp.asarray(p.ratio if p.ratio is not None else np.ones(arr.size), arr.dtype)
                arr = jnp.reshape(v * ratio, arr.shape).astype(arr.dtype)
            else:
                arr = arr.at[p.index].set(v)
            out[p.key] = arr
        return out

    def describe(self, values) -> dict[str, float]:
        """Values by parameter name.

        Args:
          values: ``[n]``.

        Returns:
          ``{name: float}``.
        """
        return {name: float(v) for name, v in zip(self.names, np.asarray(values))}


# ---------------------------------------------------------------------------------------------------- models
