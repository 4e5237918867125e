"""The linear scene solves (:mod:`jaxbpm.dsm.linear`): the stiffness tolerance and the geometric correction."""

import pytest

import jaxbpm
from jaxbpm import dsm, SceneError
from jaxbpm.scenes import UniaxialCompression


def test_stiffness_tolerance_stops_sooner_within_its_bound(packing):
    scene = UniaxialCompression(strain=0.002)
    tight = jaxbpm.solve(packing, scene, method="dsm", linear_tol=1e-10)
    for stol in (1e-2, 1e-4):
        loose = jaxbpm.solve(packing, scene, method="dsm", stiffness_tol=stol, linear_tol=1e-10)
        assert loose.stats["converged"] and loose.stats["iterations"] < tight.stats["iterations"]
        # the energy of the CG iterate is an upper bound that settles from above
        assert 0 <= loose.stiffness / tight.stiffness - 1 < stol, (stol, loose.stiffness / tight.stiffness - 1)


def test_geometric_correction_is_second_order(packing):
    """The linear bonds-only K corrected by the exact bond law's work along the linear field: within a few 1e-4 of
    the nonlinear DSM at 2 % strain, where the linear K is several 1e-3 stiff; the error shrinks faster than
    the linear one with the strain (second order); a second solve compiles nothing; contacts are refused."""
    errors = {}
    for strain in (0.005, 0.02):
        scene = UniaxialCompression(strain=strain)
        nonlinear = jaxbpm.solve(packing, scene, method="dsm", nonlinear=True).stiffness
        r = jaxbpm.solve(packing, scene, method="dsm", nonlinear=False, geometric_correction=True)
        linear = jaxbpm.solve(packing, scene, method="dsm", nonlinear=False).stiffness
        assert r.stats["stiffness_linear"] == pytest.approx(linear, rel=1e-9)
        assert r.stats["geometric_correction"] == pytest.approx(r.stiffness / linear - 1, rel=1e-9)
        assert len(r.displacement) == len(r.force) == 1 + dsm.linear.CORRECTION_POINTS
        errors[strain] = (abs(linear / nonlinear - 1), abs(r.stiffness / nonlinear - 1))
    lin2, cor2 = errors[0.02]
    assert lin2 > 3e-3 and cor2 < 0.1 * lin2 and cor2 < 5e-4
    lin05, cor05 = errors[0.005]
    assert cor05 < 0.1 * lin05
    assert cor2 / cor05 > lin2 / lin05  # the residual grows faster with the strain than the linear error
    before = dsm.linear.path_work_program.compilations
    again = jaxbpm.solve(packing, UniaxialCompression(strain=0.02), method="dsm", nonlinear=False,
                         geometric_correction=True)
    assert dsm.linear.path_work_program.compilations == before
    assert again.stiffness == pytest.approx(r.stiffness, rel=1e-12)  # (r: the loop's last solve, at 2 %)
    with pytest.raises(SceneError, match="geometric_correction"):
        jaxbpm.solve(packing, UniaxialCompression(strain=0.02, contacts=True), method="dsm", nonlinear=False,
                     geometric_correction=True)
    with pytest.raises(SceneError, match="geometric_correction"):
        jaxbpm.solve(packing, UniaxialCompression(strain=0.02), method="dsm", nonlinear=True,
                      geometric_correction=True)
