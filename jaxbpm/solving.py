"""``jaxbpm.solve(sample, scene, method=...)``: one entry point for every solver."""

from __future__ import annotations

from jaxbpm import dem, dsm, ste
from jaxbpm._geometry import check_three_d, SOLVERS_2D
from jaxbpm._options import METHODS, resolve_options, SolverOptions
from jaxbpm.auto import solve_auto
from jaxbpm.elastic_field import dsm_field
from jaxbpm.errors import SceneError
from jaxbpm.physics.model import check_params
from jaxbpm.result import Result
from jaxbpm.sample import Sample
from jaxbpm.scenes import Scene, scene_from_name

__all__ = ["solve", "METHODS"]


def solve(sample: Sample, scene, method="dem", *, params=None, **options) -> Result:
    """Solve ``scene`` on ``sample`` with a solver and return a :class:`~jaxbpm.result.Result`.

    The solver and its options: a name with keyword options (``method="dsm", tol=1e-6``) or an options object,
    :class:`jaxbpm.DEM`, :class:`jaxbpm.DSM` or :class:`jaxbpm.STE` (where each option is documented), whose values
    keyword options override (``solve(sample, scene, jaxbpm.DSM(dofs=3), tol=1e-6)``). ``method="auto"`` (options
    ``tol``, the relative stiffness error allowed against the DEM, default 0.01; ``throw``; ``progress``) runs the
    cheapest solver expected to meet ``tol`` on this scene (:mod:`jaxbpm.auto`) and says which and why in
    ``stats["method_choice"]``.

    A scene that adds particles to the sample (``ThreePointBending(rollers=True)``, through its ``stage``) adds
    them first; the solvers see them as the last particles, and ``stats["added_particles"]`` counts them.

    Failure is data: ``Result.status`` is a :class:`~jaxbpm.status.Status`, the same for every solver. ``throw``
    (every solver, default True) raises the status's error (a :class:`~jaxbpm.errors.SolveError` carrying the result
    in its ``result``); ``throw=False`` returns the result and the caller reads its status (``stats["failure"]``
    says what went wrong). An interruption always raises :class:`~jaxbpm.errors.SimulationInterrupted`.

    Args:
      sample: the bonded sample.
      scene: the scene (boundary conditions and loading), e.g. :class:`~jaxbpm.scenes.UniaxialCompression`, or its
        name (``"uniaxial"``, ``"ucs"``, ``"bts"``, ``"tpb"``; see :mod:`jaxbpm.scenes.names`).
      method: ``"dem"``, ``"dsm"``, ``"ste"``, ``"auto"`` or an options object.
      params: ``{"bond_E": [...], "bond_nu": [...], ...}`` overriding the sample's material table (for
        calibration; see :func:`jaxbpm.physics.model.check_params`).
      **options: the solver's options (the fields of its options class).

    Returns:
      The :class:`~jaxbpm.result.Result`.

    Raises:
      OptionsError: an unknown solver or option (with the closest names) or an option out of its range.
      SceneError: a scene the solver does not model (a static solver asked for a scene with bond breakage: the DSM
        and STE give the elastic range only, ``method="dem"`` the strength), an unknown scene name, or parameters
        that do not fit the sample.
      SolveError: with ``throw=True``, a solve that did not converge.
    """
    from jaxbpm import _interrupt

    with _interrupt.guard():  # a Ctrl-C swallowed on the way (in a garbage-collection callback) still stops it
        result = _solve(sample, scene, method, params, options)
        _interrupt.check()
    return result


def _solve(sample, scene, method, params, options) -> Result:
    """:func:`solve` without the interrupt guard: checks the options, the sample, the scene and the parameters, once,
    then runs the solver."""
    if isinstance(scene, str):  # "ucs", "bts", "tpb", "uniaxial", ...: jaxbpm.scenes.names
        scene = scene_from_name(scene)
    if isinstance(sample, Sample) and hasattr(scene, "stage"):  # a scene that adds particles (rollers) adds them here
        given = sample.n_particles
        sample, scene = scene.stage(sample)
        if sample.n_particles > given:
            return _added(sample.n_particles - given, lambda: _solve(sample, scene, method, params, options))
    if isinstance(method, str) and method == "auto":  # the cheapest solver expected to meet tol: jaxbpm.auto
        return solve_auto(sample, scene, params, options, solve=_dispatch)
    method = resolve_options(method, options)
    if not isinstance(sample, Sample):
        raise TypeError(f"sample must be a jaxbpm.Sample, got {type(sample).__name__}")
    if method.method not in SOLVERS_2D:
        check_three_d(sample, f"the {method.method.upper()}")
    _check_supported(scene, method.method)
    if params is not None:  # one validation path for every solver, once per solve
        params = check_params(params, sample)
    return _dispatch(sample, scene, params, method)


def _added(count: int, run) -> Result:
    """``run()``'s result (or the result its error carries) with ``stats["added_particles"] = count``: the particles
    the scene added to the sample (the last rows of the per-particle outputs)."""
    from jaxbpm.errors import SimulationInterrupted, SolveError

    try:
        result = run()
    except (SolveError, SimulationInterrupted) as e:
        if getattr(e, "result", None) is not None:
            e.result.stats["added_particles"] = count
        raise
    result.stats["added_particles"] = count
    return result


def _check_supported(scene, name: str) -> None:
    """Raise :class:`SceneError` where the solver ``name`` does not model ``scene``."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a jaxbpm scene (jaxbpm.scenes.UniaxialCompression, ThreePointBending, "
                        f"BrazilianDisc or a class following jaxbpm.scenes.Scene), got {type(scene).__name__}")
    allowed = scene.methods
    if name not in allowed:
        raise SceneError(f"{type(scene).__name__} needs method={allowed[0]!r}"
                         f"{'' if len(allowed) == 1 else f' (or one of {allowed[1:]})'}: the {name.upper()} does "
                         "not model it")
    if name != "dem" and getattr(scene, "breakage", None) is True:
        raise SceneError(f"{type(scene).__name__} with breakage=True asks for failure: the {name.upper()} gives the "
                         "elastic range only (no bond breaks in a static solve); method='dem' gives the strength. "
                         "For the elastic range, give the scene with breakage=False (e.g. UniaxialCompression())")
    if name != "dem" and scene.contacts and scene.cohesive_law is not None:
        raise SceneError(f"the cohesive contact law depends on the loading history: it needs method='dem', not "
                         f"{name!r}")


def _dispatch(sample, scene, params, options: SolverOptions) -> Result:
    """Run the solver of ``options`` on ``scene`` (one it models) with checked ``params`` (``None``: the sample's
    own)."""
    if options.method == "dsm":
        return dsm.solve_scene(sample, scene, params, options)
    if options.method == "ste":
        return ste.solve_scene(sample, scene, params, options)
    if options.start == "elastic":  # the DSM's elastic state is where the run starts
        return dem.solve_scene(sample, scene, params, options, static=dsm_field)
    return dem.solve_scene(sample, scene, params, options)
