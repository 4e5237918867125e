"""``jaxbpm.solve(sample, scene, method="auto", tol=0.01)``: the cheapest solver expected to meet ``tol``.

The rule (:func:`choose`) holds an upper envelope of each route's relative stiffness error against the DEM (the
constants below; ``docs/methods.md``, "Which method when", shows the benchmarks they bound) and takes the first
route, cheapest first, whose envelope is within ``tol``:

    STE  <  linear DSM, bonds only  <  the same, geometrically corrected  <  linear DSM, contacts linearised
         <  nonlinear DSM  <  DEM

* **DEM** for anything past elasticity or not covered: a scene that breaks bonds (``sample_breaks``), cohesive
  contacts, a scene other than :class:`~jaxbpm.scenes.UniaxialCompression` (or one whose ``methods`` are the DEM's
  alone), and a ``tol`` below every static route's envelope. The DEM is the reference: its own error is taken as 0.
* **STE** (bonds only, no walls): :data:`STE_BONDS_ERROR`; never with contacts.
* **Linear DSM, bonds only**: the bonds' geometric nonlinearity, ``g = GEOMETRIC_SLOPE x strain +
  GEOMETRIC_FLOOR`` (:func:`geometric_error`); on a scene with contacts plus their share ``s`` of the stiffness
  (the bonds-only solve leaves them out: its error is ``-s``), taken :data:`SHARE_UNCERTAINTY` larger (the share
  comes from the linearised contacts, which are soft).
* **Linear DSM, bonds only, geometrically corrected** (``geometric_correction=True``: the exact bond law's work
  along the linear displacement field, second order, :func:`jaxbpm.dsm.linear.geometric_stiffness`):
  ``CORRECTED_SLOPE x strain^2 + CORRECTED_FLOOR`` (:func:`corrected_error`) up to :data:`CORRECTED_MAX_STRAIN`.
* **Linear DSM with linearised contacts** (``nonlinear=False``): ``h(s)``, :data:`LINEARISED_ENVELOPE` against the
  share. Up to a 70 % share the linearisation makes it soft and the bonds' geometric nonlinearity stiff, so
  ``max(g, h)`` bounds the sum; beyond, ``g + h``.
* **Nonlinear DSM** (Hertz contacts sliding at the Coulomb limit; walls): :data:`NONLINEAR_BONDS_ERROR` on bonds
  only, :data:`NONLINEAR_ENVELOPE` against the share with contacts. It runs with ``throw=False``: a solve that stops
  above its tolerance is replaced by the DEM (``stats["method_choice"]["fallback"]``).

The contact share ``s = 1 - K_bonds / K_contacts`` comes from one cheap linear pass: the linear DSM on the bonds
alone and with the contacts linearised (two linear solves, the second of two passes). Where the choice is one of
those two solves its result is returned (no second solve). Where the bonds' geometric envelope ``g`` alone keeps
the linearised contacts out, the probe's bonds-only field gives ``g`` itself (its geometric correction): the bonds
carry ``1 - s`` of the stiffness, so the sum's geometric part is ``+g (1 - s)`` and, up to a 70 % share, the
contacts' part lies in ``[-h, 0]``: the error is within ``max(g (1 - s), h - g (1 - s))`` plus the correction's own
envelope (``stats["method_choice"]["geometric_error"]``). On a scene with walls the pass runs between clamped
layers (the linear DSM has no walls), for the share only, and the walls need the nonlinear DSM or the DEM.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import time
from typing import Callable

import numpy as np

from jaxbpm import dsm
from jaxbpm._geometry import check_three_d
from jaxbpm._options import resolve_options, SolverOptions
from jaxbpm.dsm.options import DSM
from jaxbpm.errors import SceneError, SolveError
from jaxbpm.physics.model import check_params
from jaxbpm.result import Result, settle
from jaxbpm.sample import Sample

__all__ = ["choose", "solve_auto", "DEFAULT_TOL", "ROUTES", "OPTIONS"]

DEFAULT_TOL = 0.01
OPTIONS = ("tol", "throw", "progress")
#: the routes, cheapest first
ROUTES = ("ste", "dsm_bonds", "dsm_bonds_corrected", "dsm_linearised", "dsm_nonlinear", "dem")

#: the STE's error envelope on bonds-only random packings
STE_BONDS_ERROR = 0.25
#: the linear bonds-only DSM's geometric nonlinearity: error ~ GEOMETRIC_SLOPE x strain + GEOMETRIC_FLOOR
GEOMETRIC_SLOPE, GEOMETRIC_FLOOR = 0.6, 0.001
#: (contact share, |error|) of the linear DSM with linearised contacts, beyond the bonds' own ``g``; linear between
#: the points
LINEARISED_ENVELOPE = ((0.0, 0.005), (0.1, 0.01), (0.25, 0.02), (0.45, 0.05), (0.7, 0.07), (0.77, 0.17),
                       (0.82, 0.2), (0.9, 0.35), (0.93, 0.8), (1.0, math.inf))
#: (contact share, |error|) of the nonlinear DSM when Newton converges (one that does not falls back to the DEM)
NONLINEAR_ENVELOPE = ((0.0, 0.003), (0.71, 0.003), (0.77, 0.01), (0.9, 0.01), (0.93, 0.06), (1.0, 0.06))
#: the nonlinear DSM on bonds only (geometric nonlinearity solved)
NONLINEAR_BONDS_ERROR = 0.001
#: the linear bonds-only DSM with its geometric correction: error ~ CORRECTED_SLOPE x strain^2 + CORRECTED_FLOOR, up
#: to CORRECTED_MAX_STRAIN (beyond: not used)
CORRECTED_SLOPE, CORRECTED_FLOOR, CORRECTED_MAX_STRAIN = 1.0, 0.0015, 0.05
#: the contacts' share from the linear pass is low by up to this fraction of itself (the linearised contacts are
#: soft)
SHARE_UNCERTAINTY = 0.25
#: stiffness_tol of the linear DSM routes when tol >= LOOSE_TOL (K within 0.2 % of the converged answer); below,
#: the DSM's default
LOOSE_TOL, LOOSE_STIFFNESS_TOL = 0.01, 1e-2


def check_tol(tol) -> float:
    """``tol`` as a float.

    Args:
      tol: the relative stiffness error allowed against the DEM.

    Returns:
      ``float(tol)``.

    Raises:
      SceneError: ``tol`` is not a number in (0, 1).
    """
    if isinstance(tol, bool) or not isinstance(tol, numbers.Real) or not (0 < float(tol) < 1):
        raise SceneError(f"method='auto' takes tol, the relative stiffness error allowed against the DEM, in (0, 1) "
                         f"(e.g. 0.01 for 1 %), got {tol!r}")
    return float(tol)


def _envelope(table, s) -> float:
    xs, ys = zip(*table)
    s = min(max(float(s), 0.0), 1.0)
    k = int(np.searchsorted(xs, s, side="right")) - 1
    if k >= len(xs) - 1:
        return ys[-1]
    x0, x1, y0, y1 = xs[k], xs[k + 1], ys[k], ys[k + 1]
    if math.isinf(y1):
        return y0 if s == x0 else math.inf
    return y0 + (s - x0) * (y1 - y0) / (x1 - x0)


def geometric_error(strain) -> float:
    """Envelope of the linear DSM's relative error from the bonds' geometric nonlinearity.

    Args:
      strain: the scene's strain.

    Returns:
      ``GEOMETRIC_SLOPE x strain + GEOMETRIC_FLOOR``.
    """
    return GEOMETRIC_SLOPE * float(strain) + GEOMETRIC_FLOOR


def corrected_error(strain) -> float:
    """Envelope of the linear bonds-only DSM's relative error after its geometric correction.

    Args:
      strain: the scene's strain.

    Returns:
      ``CORRECTED_SLOPE x strain^2 + CORRECTED_FLOOR``; ``inf`` beyond :data:`CORRECTED_MAX_STRAIN`.
    """
    strain = abs(float(strain))
    return CORRECTED_SLOPE * strain**2 + CORRECTED_FLOOR if strain <= CORRECTED_MAX_STRAIN else math.inf


def expected_errors(scene, share, geometric=None) -> dict:
    """The envelope of each route's relative error against the DEM.

    Args:
      scene: the scene (its strain and walls).
      share: the contacts' share of the stiffness (``None``: no contacts; ``nan``: unknown, taken as
        contact-dominated).
      geometric: the linear bonds-only solve's geometric error from its own field (its K over the corrected one,
        less 1); ``None``: the envelope :func:`geometric_error` stands in.

    Returns:
      ``{route: error}`` for every route of :data:`ROUTES` (``inf``: the route does not model the scene).
    """
    g = geometric_error(scene.strain) if geometric is None else abs(float(geometric))
    gc = corrected_error(scene.strain)
    walls = bool(scene.uses_walls)
    if share is None:
        return {"ste": math.inf if walls else STE_BONDS_ERROR, "dsm_bonds": math.inf if walls else g,
                "dsm_bonds_corrected": math.inf if walls else gc, "dsm_linearised": math.inf,
                "dsm_nonlinear": NONLINEAR_BONDS_ERROR if not walls else NONLINEAR_ENVELOPE[0][1], "dem": 0.0}
    s = 1.0 if not np.isfinite(share) else max(float(share), 0.0)
    if walls:
        linearised = math.inf
    elif geometric is None:
        linearised = _linearised_error(g, s)
    else:
        linearised = _linearised_error_measured(g, s) + gc
    # the bonds-only routes miss the contacts' share, which the probe measured with the linearised contacts
    missed = s * (1.0 + SHARE_UNCERTAINTY)
    return {"ste": math.inf, "dsm_bonds": math.inf if walls else g + missed,
            "dsm_bonds_corrected": math.inf if walls else gc + missed, "dsm_linearised": linearised,
            "dsm_nonlinear": _envelope(NONLINEAR_ENVELOPE, s), "dem": 0.0}


def _linearised_error(g, s) -> float:
    """Envelope of the linear DSM with linearised contacts: up to a 70 % share the linearisation makes it soft
    while the bonds' geometric nonlinearity makes it stiff (``g``, positive), so the larger of the two bounds their
    sum; beyond, where it turns stiff too, they add."""
    h = _envelope(LINEARISED_ENVELOPE, s)
    return max(g, h) if s <= 0.7 else g + h


def _linearised_error_measured(g, s) -> float:
    """The same with the bonds' geometric error ``g`` measured (the probe's bonds-only field): the bonds carry
    ``1 - s`` of the stiffness, so the sum's geometric part is ``+g (1 - s)``; the contacts' part lies in
    ``[-h, 0]`` up to a 70 % share (the sum in ``[g (1 - s) - h, g (1 - s)]``), beyond in ``[0, h]``."""
    h = _envelope(LINEARISED_ENVELOPE, s)
    gb = g * (1.0 - s)
    return max(gb, h - gb) if s <= 0.7 else gb + h


def _linearised_best_case(s) -> float:
    """The least :func:`_linearised_error_measured` can give at share ``s`` whatever ``g`` is measured."""
    h = _envelope(LINEARISED_ENVELOPE, s)
    return 0.5 * h if s <= 0.7 else h


def _dem_only(sample, scene) -> str | None:
    """Why ``scene`` needs the DEM (``None``: an elastic compression the static methods model)."""
    from jaxbpm.scenes import sample_breaks

    allowed = scene.methods
    if not ({"dsm", "ste"} & set(allowed)):
        return f"{type(scene).__name__} is modelled by the DEM only (methods={tuple(allowed)})"
    if not {"dsm", "ste"} <= set(allowed):
        return (f"the static methods were validated on uniaxial compression only, not on {type(scene).__name__}: "
                "the DEM")
    if sample_breaks(sample, scene.breakage):
        return "the scene breaks bonds (breakage, or finite bond strengths): past elasticity, the DEM only"
    if scene.contacts and scene.cohesive_law is not None:
        return "cohesive contacts depend on the loading history: the DEM only"
    return None


def _linear_options(tol) -> dict:
    return {"stiffness_tol": LOOSE_STIFFNESS_TOL} if tol >= LOOSE_TOL else {}


def _probe(sample, scene, params, tol):
    """The cheap linear pass: ``(share, bonds_result, linearised_result, seconds, note)``."""
    layers = scene if not scene.uses_walls else dataclasses.replace(scene, boundary="layers")
    t = time.perf_counter()
    res_b = res_c = None
    note = ""
    linear = DSM(nonlinear=False, throw=False, **_linear_options(tol))
    try:
        res_b = dsm.solve_scene(sample, dataclasses.replace(layers, contacts=False), params, linear)
        res_c = dsm.solve_scene(sample, layers, params, linear)
    except (SceneError, SolveError) as exc:  # e.g. particles held by contacts only: no bonds-only answer
        note = f"; the linear pass failed ({type(exc).__name__}: {str(exc).splitlines()[0][:200]})"
    seconds = time.perf_counter() - t
    ok = [r is not None and r.status.ok and np.isfinite(r.stiffness) and r.stiffness > 0
          for r in (res_b, res_c)]
    if not all(ok):
        if not note:
            note = "; the linear pass did not converge"
        return math.nan, res_b if ok[0] else None, res_c if ok[1] else None, seconds, note
    return 1.0 - res_b.stiffness / res_c.stiffness, res_b, res_c, seconds, note


@dataclasses.dataclass
class Choice:
    """What :func:`choose` decided.

    Attributes:
      method: the solver (``"ste"``, ``"dsm"``, ``"dem"``).
      options: the solver's options that differ from its defaults (a dict; ``solver_options`` is the object).
      route: the route's name (one of :data:`ROUTES`).
      why: the reason, in words.
      scene: the scene to solve (the bonds-only routes solve it without contacts).
      tol: the tolerance the choice meets.
      contact_share: the contacts' share of the stiffness from the linear pass (``None``: no contacts).
      expected: each route's error envelope.
      probe_time: the linear pass's seconds.
      probe: the linear pass's results by route (reused when the route is one of them).
      geometric_error: the bonds' geometric error from the probe's field, where measured.
    """

    method: str
    options: dict
    route: str
    why: str
    scene: object
    tol: float
    contact_share: float | None = None
    expected: dict | None = None
    probe_time: float = 0.0
    probe: dict = dataclasses.field(default_factory=dict)
    geometric_error: float | None = None

    @property
    def solver_options(self) -> SolverOptions:
        """The options object of the chosen solver (``options`` checked)."""
        return resolve_options(self.method, self.options)

    def record(self) -> dict:
        """The ``stats["method_choice"]`` entry."""
        share = self.contact_share
        return {"method": self.method, "route": self.route, "options": dict(self.options), "why": self.why,
                "tol": self.tol, "contact_share": None if share is None or not np.isfinite(share) else float(share),
                "expected_error": None if self.expected is None else {
                    k: (None if math.isinf(v) else float(v)) for k, v in self.expected.items()},
                "probe_time": float(self.probe_time), "reused_probe": self.route in self.probe,
                "geometric_error": None if self.geometric_error is None else float(self.geometric_error)}


_DESCRIBE = {"ste": "the STE", "dsm_bonds": "the linear DSM on the bonds alone",
             "dsm_bonds_corrected": "the linear DSM on the bonds alone, geometrically corrected",
             "dsm_linearised": "the linear DSM with the contacts linearised",
             "dsm_nonlinear": "the nonlinear DSM", "dem": "the DEM"}


def choose(sample, scene, tol=DEFAULT_TOL, *, params=None) -> Choice:
    """The cheapest route whose error envelope is within ``tol`` (see the module docstring).

    On a scene with Hertz contacts this runs the linear pass that measures the contacts' share of the stiffness.

    Args:
      sample: the bonded sample.
      scene: the scene.
      tol: the relative stiffness error allowed against the DEM, in (0, 1).
      params: parameters overriding the sample's, checked by :func:`~jaxbpm.physics.model.check_params`
        (``None``: its own).

    Returns:
      The :class:`Choice`.
    """
    tol = check_tol(tol)
    reason = _dem_only(sample, scene)
    if reason is not None:
        return Choice("dem", {}, "dem", reason, scene, tol)
    contacts = bool(scene.contacts)
    share, probe, seconds, note = None, {}, 0.0, ""
    if contacts:
        share, res_b, res_c, seconds, note = _probe(sample, scene, params, tol)
        if not scene.uses_walls:
            probe = {k: r for k, r in (("dsm_bonds", res_b), ("dsm_linearised", res_c)) if r is not None}
    expected = expected_errors(scene, share)
    route = next(r for r in ROUTES if expected[r] <= tol)
    geometric = None
    if (contacts and "dsm_bonds" in probe and np.isfinite(share)
            and ROUTES.index(route) > ROUTES.index("dsm_linearised")
            and _linearised_best_case(share) + corrected_error(scene.strain) <= tol):
        # the bonds' geometric error, measured on the probe's bonds-only field, may let the linearised contacts in
        seconds += _correct_probe(sample, scene, params, probe)
        if "dsm_bonds_corrected" in probe:
            corrected = probe["dsm_bonds_corrected"]
            geometric = corrected.stats["stiffness_linear"] / corrected.stiffness - 1.0
            expected = expected_errors(scene, share, geometric)
            route = next(r for r in ROUTES if expected[r] <= tol)
            note += f"; the bonds' geometric error measured on its bonds-only field: {100 * geometric:+.2g} %"
    if route == "dsm_bonds_corrected" and "dsm_bonds" in probe and route not in probe:
        seconds += _correct_probe(sample, scene, params, probe)
    # the STE's envelope was measured on its free-surface form, the closer to the DEM on random packings
    options = {"ste": {"boundary": "free"}, "dsm_bonds": {"nonlinear": False, **_linear_options(tol)},
               "dsm_bonds_corrected": {"nonlinear": False, "geometric_correction": True, **_linear_options(tol)},
               "dsm_linearised": {"nonlinear": False, **_linear_options(tol)},
               "dsm_nonlinear": {"nonlinear": True}, "dem": {}}[route]
    method = {"ste": "ste", "dem": "dem"}.get(route, "dsm")
    what = ("bonds only" if not contacts else
            f"contacts carry {100 * share:.1f} % of the stiffness (linear pass)" if np.isfinite(share) else
            "contact share unknown, taken as contact-dominated")
    if scene.uses_walls:
        what += "; walls (the linear DSM has none)"
    cheaper = [r for r in ROUTES[:ROUTES.index(route)] if np.isfinite(expected[r])]
    why = f"{what}{note}: {_DESCRIBE[route]} is the cheapest method expected within tol = {tol:g} " \
          f"(measured error envelope {100 * expected[route]:.2g} %)"
    if cheaper:
        why += "; cheaper: " + ", ".join(f"{_DESCRIBE[r][4:]} {100 * expected[r]:.2g} %" for r in cheaper)
    solve_scene = dataclasses.replace(scene, contacts=False) if route.startswith("dsm_bonds") and contacts else scene
    return Choice(method, options, route, why, solve_scene, tol, share, expected, seconds, probe, geometric)


def _correct_probe(sample, scene, params, probe) -> float:
    """Add the probe's bonds-only result with its geometric correction to ``probe`` as ``"dsm_bonds_corrected"``
    (nothing where that fails); returns the seconds it took."""
    from jaxbpm.dsm.linear import with_geometric_correction

    t = time.perf_counter()
    try:
        probe["dsm_bonds_corrected"] = with_geometric_correction(
            probe["dsm_bonds"], sample, dataclasses.replace(scene, contacts=False), params)
    except (SceneError, SolveError, FloatingPointError):
        pass
    return time.perf_counter() - t


def _probe_compile_time(choice) -> float:
    """The compile time of the probe's solves, each counted once (the corrected bonds-only result holds the bonds-only
    solve's own)."""
    probes = dict(choice.probe)
    if "dsm_bonds_corrected" in probes:
        probes.pop("dsm_bonds", None)
    return sum(r.compile_time for r in probes.values())


def solve_auto(sample, scene, params, options: dict, solve: Callable[..., Result]) -> Result:
    """``jaxbpm.solve(..., method="auto", tol=..., throw=..., progress=...)``.

    Args:
      sample: the bonded sample.
      scene: the scene.
      params: parameters (``None``: the sample's own), checked here.
      options: ``tol``, ``throw`` and ``progress``.
      solve: ``solve(sample, scene, params, options_object) -> Result``, the solvers' dispatch
        (:func:`jaxbpm.solving.solve` passes its own).

    Returns:
      The chosen solver's :class:`~jaxbpm.result.Result`, ``stats["method_choice"]`` saying which and why.
    """
    unknown = sorted(set(options) - set(OPTIONS))
    if unknown:
        raise SceneError(f"method='auto' takes only {', '.join(OPTIONS)}; got {', '.join(map(repr, unknown))} "
                         "(choose a method to pass its options)")
    if not isinstance(sample, Sample):
        raise TypeError(f"sample must be a jaxbpm.Sample, got {type(sample).__name__}")
    tol = check_tol(options.get("tol", DEFAULT_TOL))
    throw = options.get("throw", True)
    if not isinstance(throw, bool):
        raise SceneError(f"throw must be True or False, got {throw!r}")
    if params is not None:  # once per solve: the solvers below take them as they are
        params = check_params(params, sample)
    if sample.dim == 2:
        return _plane(sample, scene, params, throw, solve, tol)
    t0 = time.perf_counter()
    choice = choose(sample, scene, tol, params=params)
    result, fallback, total, compile_time = _answer(sample, choice, params, options, throw, solve, t0)
    _account(result, choice, fallback, total, compile_time)
    return result


def _plane(sample, scene, params, throw, solve, tol) -> Result:
    """``method="auto"`` on a two-dimensional sample: the linear DSM (exact for the linear model of bonds between
    clamped layers); the DEM where bonds break or discs touch by the linear law (the DSM has neither in 2D); other
    scenes are refused."""
    linear = bool(scene.contacts) and scene.linear_law is not None
    if (scene.breakage is True or linear) and not scene.uses_walls and (linear or not scene.contacts):
        result = solve(sample, scene, params, resolve_options("dem", {"throw": throw}))
        result.stats["method_choice"] = {
            "method": "dem", "route": "dem", "options": {}, "tol": tol, "contact_share": None, "expected_error": None,
            "probe_time": 0.0, "reused_probe": False, "geometric_error": None,
            "why": "a two-dimensional sample with breakage or linear contacts: the DEM (the DSM of 2D samples has "
                   "neither)"}
        return result
    if scene.breakage is True or scene.contacts or scene.uses_walls:
        check_three_d(sample, "method='auto' on a scene with breakage, Hertz or cohesive contacts, or walls")
    result = solve(sample, scene, params, resolve_options("dsm", {"throw": throw}))
    result.stats["method_choice"] = {
        "method": "dsm", "route": "dsm_bonds", "options": {}, "tol": tol, "contact_share": None,
        "expected_error": None, "probe_time": 0.0, "reused_probe": False, "geometric_error": None,
        "why": "a two-dimensional sample with bonds only between clamped layers: the linear DSM on the bonds alone "
               "(the solver of 2D samples so far)"}
    return result


def _answer(sample, choice: Choice, params, options, throw, solve, t0):
    """The chosen solver's result: ``(result, fallback, seconds, compile_time)`` (``fallback``: why the nonlinear
    DSM gave way to the DEM, else ``None``)."""
    fallback = None
    if choice.route in choice.probe:  # the linear pass is the answer: no second solve
        result = dataclasses.replace(choice.probe[choice.route], stats=dict(choice.probe[choice.route].stats))
        result = settle(result, throw)
        total = choice.probe_time
        compile_time = _probe_compile_time(choice)
    else:
        progress = {"progress": options["progress"]} if "progress" in options else {}
        opts = choice.solver_options.replace(throw=throw, **(progress if choice.method == "dem" else {}))
        if choice.route == "dsm_nonlinear":  # accepted where Newton converges, else the DEM
            first = solve(sample, choice.scene, params, opts.replace(throw=False))
            if first.status.ok:
                result = first
            else:
                fallback = {"status": str(first.status), "failure": first.stats.get("failure"),
                            "wall_time": first.wall_time}
                result = solve(sample, choice.scene, params, resolve_options("dem", {"throw": throw, **progress}))
        else:
            result = solve(sample, choice.scene, params, opts)
        total = time.perf_counter() - t0
        compile_time = result.compile_time + _probe_compile_time(choice)
    return result, fallback, total, compile_time


def _account(result, choice: Choice, fallback, total, compile_time) -> None:
    """The choice's time in ``result`` (the linear pass counts as setup and compilation) and its
    ``stats["method_choice"]``."""
    # the wall time covers the choice (the linear pass) and the answer; what is not the answer's own compile or
    # run counts as setup
    extra_compile = compile_time - result.compile_time
    extra_setup = max(total - result.wall_time - extra_compile, 0.0)
    result.wall_time = result.wall_time + extra_setup + extra_compile
    result.setup_time = result.setup_time + extra_setup
    result.compile_time = compile_time
    result.stats["method_choice"] = record = choice.record()
    if fallback is not None:
        record.update(method="dem", route="dem", options={}, fallback=fallback,
                      why=record["why"] + f"; the nonlinear DSM stopped with status {fallback['status']!r}: the DEM")
