"""``jaxbpm.solve(sample, scene, method=...)``: one entry point for every solver."""

from __future__ import annotations

from jaxbpm.errors import SceneError
from jaxbpm.result import Result
from jaxbpm.sample import Sample

__all__ = ["solve", "METHODS"]

METHODS = ("dem", "dsm", "ste")


def solve(sample: Sample, scene, method="dem", *, params=None, **options) -> Result:
    """Solve ``scene`` on ``sample`` with ``method`` and return a :class:`~jaxbpm.result.Result`.

    method: ``"dem"``, ``"dsm"`` or ``"ste"`` with keyword options, or an options object -- ``jaxbpm.DEM(...)``,
    ``jaxbpm.DSM(...)``, ``jaxbpm.STE(...)`` (:mod:`jaxbpm.options`: checked when built, hashable) -- whose options
    keywords given here override. An unknown option raises :class:`~jaxbpm.errors.SceneError` with the closest
    names. ``method="auto"`` (options ``tol``, the relative stiffness error allowed against the DEM, default 0.01;
    ``throw``; ``progress``) runs the cheapest method expected to meet ``tol`` on this scene (:mod:`jaxbpm.auto`;
    on a scene with contacts after a linear pass that measures their share of the stiffness) and says which and
    why in ``stats["method_choice"]``.

    Failure is data: ``Result.status`` is ``"converged"``, ``"max_iterations"`` (an iterative solve stopped above its
    tolerance), ``"unstable"`` (the DEM blew up), ``"interrupted"`` or ``"not_finite"`` (the stiffness is NaN or
    infinite), the same for every method. ``throw`` (every method, default True) raises the matching
    :class:`~jaxbpm.errors.SolveError` -- :class:`~jaxbpm.errors.ConvergenceError`,
    :class:`~jaxbpm.errors.InstabilityError`, :class:`~jaxbpm.errors.NotFiniteError` -- carrying the result in its
    ``result``; ``throw=False`` returns the result and the caller reads its status (``stats["failure"]`` says what
    went wrong). An interruption always raises :class:`~jaxbpm.errors.SimulationInterrupted`.

    params: ``{"bond_E": [...], "bond_nu": [...]}`` overriding the sample's material table (for calibration).
    options for ``"dem"``: ``dt`` (time step [s], default ``safety`` x critical), ``safety`` (0.5), ``damping`` (local
    damping coefficient alpha, 0.7), ``loading_time`` [s] (default ``transits`` x the time a wave needs to cross the
    sample along the axis, estimated from the mean bond; ``transits`` = 40), ``chunk`` (steps per jitted chunk),
    ``progress`` (print progress, or a callable ``progress(steps_done, steps_total, elapsed_s)``), ``neighbors``
    (:class:`~jaxbpm.dem.NeighborSettings`), ``max_records`` (points kept in the returned curve, 2000),
    ``record_to`` (an ``.h5`` path: every step's time, displacement, force, reactions and broken-bond counts are
    appended chunk by chunk as they arrive, see :mod:`jaxbpm.dem.records`; an existing file is replaced only when it
    is a record of the same run or with ``overwrite=True``), ``snapshots`` and ``vtu`` (``snapshots=K``
    frames evenly spaced in time, the first at rest, written to the ParaView series ``vtu="dir/run.pvd"`` as the run
    goes: displacement, velocity, force and broken bonds (tensile, shear) per particle; per bond ``intact``,
    ``break_mode`` and ``broken_time``). A ``KeyboardInterrupt`` during the run (Ctrl-C, or raised by the
    ``progress`` callable) raises :class:`~jaxbpm.errors.SimulationInterrupted`, whose ``result`` is the
    :class:`Result` of the part that was run (``interrupted=True``; the record file is kept, status
    ``"interrupted"``, and the state after the last completed chunk is saved in it).
    ``resume`` (the ``.h5`` record of an interrupted run): continue that run from its saved state and append to its
    record, giving the same records and stiffness as an uninterrupted run (to round-off; give the same sample,
    scene and options: the record's time step, speed, damping, chunk and sample fingerprint must agree, else an
    error names what differs). A Ctrl-C before the first chunk raises a plain ``KeyboardInterrupt`` (the record
    file, if any, says ``"interrupted"``). ``pad`` (True): a bonds-only scene (no contacts, no walls) runs on the sample padded to its
    size class (:func:`jaxbpm._compile.size_class`: extra particles clamped at rest, joined by bonds without
    stiffness that never break), so that another sample of that class reuses the compiled programs; curves, time
    step, records, frames and the returned state are the sample's own (``pad=False`` runs the sample as it is). The
    default ``chunk`` is a power of two (32 to 4096 steps, 20-40 chunks a run where that range allows), so that
    samples with about the same number of steps share the compiled chunk. ``Result.setup_time`` is what comes
    before the first chunk (model, time step, loading, neighbour list, padding, initial state), ``compile_time`` the
    tracing and compiling of the programs the solve builds (0 when the process had them) and ``run_time`` the rest
    (the chunks and the work between them).
    options for ``"dsm"``: ``dofs`` (3 or 6 per particle; default: the Model's choice, 6 with bonds), ``nonlinear``
    (default: True when the scene has contacts or walls), ``tol`` (nonlinear relative residual, 1e-3),
    ``linear_tol`` (CG relative residual, 1e-6), ``maxiter``, ``newton_maxiter`` (30), ``stiffness_tol`` (linear
    solves: CG also stops once the strain energy, hence K, has settled to this relative change; nonlinear: Newton
    stops when the reaction changes less than this, relative; default ``"auto"``: 1e-6 for the linear bonds-only
    solve -- K within about 1e-7 of the residual-converged answer, a third fewer CG iterations -- and off elsewhere;
    ``None``: the residual tests alone), ``slip`` (contacts slide at the Coulomb limit, True;
    False: no slip, Jarolin & Dosta's assumption, which overestimates K where contacts slide), ``contact_skin`` [m]
    (pairs whose gap at rest is below it are contact candidates; default half the mean radius; with
    ``nonlinear=False`` four times the affine approach of two touching mean-sized particles at the linearisation
    state, 0.1 mean radii at 2 % strain, doubled up to half a radius while a pair that touches there lies more than
    half the reach apart at rest, each try's time counted in),
    ``load_steps`` (nonlinear: equal load increments, 4; K is their least-squares slope over the scene's fit range,
    as for the DEM); with ``nonlinear=False`` on a scene with contacts, the contacts are linearised (Hertz normal and
    secant Mindlin tangential stiffness, symmetric) at ``contact_fraction`` (default: the middle of the fit range)
    of the strain, first of the affine field, then of the previous solution (``contact_passes``, 2; each pass
    starts from the previous one's displacements and all but the last stop once the strain energy has settled to
    1 %); the stats hold the candidates, how many touch, the largest gap at rest of a touching pair and the
    reach's retries (a warning when a given ``contact_skin`` is that close). ``pad`` (True): the linear bonds-only solve runs on the sample
    padded to its size class (held padding particles, bonds without stiffness; same answer to round-off), so that
    samples of a class share one compiled program; its setup is kept for the last few samples, so a second solve of
    one sample costs the solve alone. ``geometric_correction`` (False; linear bonds-only solves): K corrected for
    the bonds' geometric nonlinearity from the linear displacement field (the exact bond law's work along it, a few
    force evaluations; within 0.04 % of the nonlinear DSM at 0.2-2 % strain where the linear K is 0.1-1.1 % stiff);
    ``stats["stiffness_linear"]`` keeps the linear K.
    options for ``"ste"`` (stiffness tensor estimation, no displacement computed): ``dofs`` (3, the paper's
    translations-only form, or 6), ``first_neighbour`` (Eq. 33-35 instead of Eq. 32), ``layered`` (layered
    springs in series along the load, for porous or shaped bodies), ``layer_thickness`` [m], ``contact_fraction``
    (contacts: fraction of the target strain at which Hertz contacts are linearised), ``volumes`` (``[n]`` particle
    volumes V^n), ``precision`` (``"float64"``, or ``"float32"``: 2-3x faster, ~1e-7 relative change). ``pad``
    (True: the estimator is padded to the sample's size class and kept for the last few samples, as for the DSM). The stats hold the Voigt tensor, E_x, E_y, E_z, nu, an isotropic fit and the skipped particles.
    """
    from jaxbpm import _interrupt

    with _interrupt.guard():  # a Ctrl-C swallowed on the way (in a garbage-collection callback) still stops it
        result = _solve(sample, scene, method, params, options)
        _interrupt.check()
    return result


def _solve(sample, scene, method, params, options) -> Result:
    from jaxbpm.options import options_for

    if isinstance(method, str) and method == "auto":  # the cheapest method expected to meet tol: jaxbpm.auto
        from jaxbpm.auto import solve_auto

        return solve_auto(sample, scene, params, options)
    method, options = options_for(method, options)
    if not isinstance(sample, Sample):
        raise TypeError(f"sample must be a jaxbpm.Sample, got {type(sample).__name__}")
    allowed = getattr(scene, "methods", None)
    if allowed is not None and method not in allowed:
        raise SceneError(f"{type(scene).__name__} needs method={allowed[0]!r}"
                         f"{'' if len(allowed) == 1 else f' (or one of {allowed[1:]})'}: the {method.upper()} does "
                         "not model it")
    if method != "dem" and getattr(scene, "contacts", False) and getattr(scene, "cohesive_law", None) is not None:
        raise SceneError(f"the cohesive contact law depends on the loading history: it needs method='dem', not "
                         f"{method!r}")
    if params is not None:  # one validation path for every method
        from jaxbpm.physics.model import check_params

        params = check_params(params, sample)
    if method == "dsm":
        from jaxbpm import dsm

        return dsm.solve_scene(sample, scene, params, **options)
    if method == "ste":
        from jaxbpm import ste

        return ste.solve_scene(sample, scene, params, **options)
    from jaxbpm.dem import scene as dem_scene

    return dem_scene.solve_scene(sample, scene, params, **options)
