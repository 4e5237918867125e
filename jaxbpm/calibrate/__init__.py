"""Calibration: find bond parameters that reproduce measured targets.

``jaxbpm.calibrate.calibrate(sample, scene, targets, method=..., solver=...)`` runs a calibrator (``method``) on a
solver (``solver``: ``"dsm"``, ``"ste"``, ``"dem"``, or a :class:`Forward`) and picks the cheapest route that is
accurate enough (:mod:`~jaxbpm.calibrate.dispatch`):

* ``method="auto"`` (default): multi-fidelity (:mod:`~jaxbpm.calibrate.multifidelity`): STE, then DSM only when STE's
  answer is not already within ``tol`` there; each level in closed form where it applies (bonds-only elasticity:
  stiffness is linear in a common bond modulus, :mod:`~jaxbpm.calibrate.closed_form`), else Adam.
* ``method="adam"``: optax Adam with finite-difference or autodiff gradients and Qu et al.'s options
  (:mod:`~jaxbpm.calibrate.adam`); the closed form replaces it where it applies unless ``shortcut=False``.
* ``method="surrogate"``: Irazabal et al.'s random forests with iterative range narrowing
  (:mod:`~jaxbpm.calibrate.surrogate`).
* ``method="closed-form"``: the closed form, or an error saying why it does not apply.

Young's modulus and Poisson's ratio together: :func:`calibrate_elastic` (a secant on the bond Poisson ratio, the
bond modulus in closed form; 2-4 solves, :mod:`~jaxbpm.calibrate.elastic`).

What a laboratory measures (E, nu, UCS, BTS, flexural strength) in one staged workflow: :func:`lab`
(:mod:`~jaxbpm.calibrate.lab`).

Strengths: :func:`calibrate_strength` calibrates the bond tensile and shear strengths against the UCS and the
flexural strength (Qu et al.'s original and simplified schemes, :mod:`~jaxbpm.calibrate.strength`); it is
``calibrate`` with ``Target("strength", ..., scene="ucs"/"tpb")`` on DEM failure runs.

Lower-level pieces (:class:`Target`, :class:`Parameter`, :class:`ParameterSpace`, :class:`Forward` -- a forward,
parameters to observables --, :class:`Problem` and the calibrator functions) compose the same way for custom
forwards (:meth:`Forward.from_function`). This package's ``__init__`` only re-exports them.
"""

from __future__ import annotations

from jaxbpm.calibrate.adam import GRADIENTS, adam, loss_and_gradient, tied_gradient
from jaxbpm.calibrate.closed_form import closed_form
from jaxbpm.calibrate.dispatch import METHODS, calibrate, default_parameters
from jaxbpm.calibrate.elastic import calibrate_elastic
from jaxbpm.calibrate.lab import LAB_TARGETS, LabResult, lab
from jaxbpm.calibrate.multifidelity import calibrate_level, default_levels, multifidelity
from jaxbpm.calibrate.objective import (CalibrationError, Forward, Parameter, ParameterSpace, Problem, Target,
                                        as_targets, base_params, forward_model)
from jaxbpm.calibrate.history import CalibrationResult, History, load_history, plot_history
from jaxbpm.calibrate.strength import (STRENGTH_KEYS, STRENGTH_SCHEMES, calibrate_strength, format_strength_table,
                                       strength_table)
from jaxbpm.calibrate.runs import RunSet, run_set
from jaxbpm.calibrate.surrogate import surrogate

__all__ = [
    "calibrate", "METHODS", "CalibrationError", "Target", "Parameter", "ParameterSpace", "Forward", "Problem",
    "forward_model", "default_parameters", "adam", "GRADIENTS", "loss_and_gradient", "tied_gradient", "closed_form",
    "surrogate",
    "RunSet", "run_set", "multifidelity", "default_levels", "calibrate_level", "CalibrationResult", "History",
    "plot_history", "load_history", "base_params", "calibrate_strength", "strength_table", "STRENGTH_KEYS",
    "STRENGTH_SCHEMES", "format_strength_table", "calibrate_elastic", "lab", "LabResult",
    "LAB_TARGETS", "as_targets",
]
