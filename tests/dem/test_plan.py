"""The plan of a DEM scene run: whole chunks that end the loading at its target, one plan for a single run and a
batch (the smallest critical time step, the slowest transit), padding where the scene allows it, the options
checked."""

import warnings

import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.dem.plan import default_chunk, plan, transit_time
from jaxbpm.dem.timestep import critical_time_step
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression

R = 1e-3
ELASTIC = UniaxialCompression(strain=0.002)


@pytest.fixture(scope="module")
def column():
    return jaxbpm.generate.lattice("sc", (2, 2, 5), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


def test_a_plan_ends_the_loading_at_its_target_in_whole_chunks(column):
    p = plan(column, ELASTIC, default_params(column), transits=10)
    length, area = ELASTIC.geometry(column)
    crit = critical_time_step(p.model, default_params(column))
    assert p.dt_crit == (crit,) and p.dt == 0.5 * crit
    assert p.n_steps % p.chunk == 0 and p.n_chunks == p.n_steps // p.chunk
    assert p.loading_time == 10 * transit_time(column, p.model, default_params(column), length)
    assert p.n_steps == -(-int(np.ceil(p.loading_time / p.dt)) // p.chunk) * p.chunk
    np.testing.assert_allclose(p.speed * p.n_steps * p.dt, ELASTIC.strain * length, rtol=1e-14)
    assert p.size is not None and p.model.n == p.size.particles >= column.n_particles + 2  # bonds only: padded
    assert p.load.clamped.shape == (p.size.particles,)
    assert p.attrs["damping"] == 0.7 and p.attrs["chunk"] == p.chunk and p.attrs["dt"] == p.dt
    assert plan(column, ELASTIC, default_params(column), transits=10, pad=False).size is None
    assert plan(column, UniaxialCompression(contacts=True), default_params(column), transits=10).size is None
    assert p.start is None and p.steps_left == p.n_steps
    later = p.starting_from("a state", 3 * p.chunk)
    assert later.start == "a state" and later.steps_left == p.n_steps - 3 * p.chunk and p.start is None


def test_one_plan_for_a_batch(column):
    soft, stiff = default_params(column), dict(default_params(column), bond_E=np.array([4e9]))
    one = plan(column, ELASTIC, soft, transits=10)
    both = plan(column, ELASTIC, [stiff, soft], transits=10)
    assert both.dt_crit[1] == one.dt_crit[0] and both.dt_crit[0] < both.dt_crit[1]
    assert both.dt == 0.5 * both.dt_crit[0]  # the stiffest member's time step
    assert both.loading_time == one.loading_time  # the softest member's transit
    alone = plan(column, ELASTIC, [soft], transits=10)
    for key in ("dt", "n_steps", "chunk", "speed", "loading_time"):
        assert getattr(alone, key) == getattr(one, key)


def test_default_chunk():
    assert default_chunk(100) == 32 and default_chunk(20 * 100) == 64 and default_chunk(10**7) == 4096
    assert all(c & (c - 1) == 0 for c in (default_chunk(n) for n in range(1, 5000, 37)))
    assert default_chunk(2000, snapshots=5) == 64 and default_chunk(200, snapshots=11) == 20


def test_the_time_step_is_checked(column):
    params = default_params(column)
    with pytest.raises(SceneError, match=r"safety must lie in \(0, 1\]"):
        plan(column, ELASTIC, params, safety=1.5)
    with pytest.raises(SceneError, match="dt must be a positive time step"):
        plan(column, ELASTIC, params, dt=-1e-7)
    crit = plan(column, ELASTIC, params, transits=1).dt_crit[0]
    with pytest.warns(UserWarning, match=r"above the critical time step estimate .* \(2\.00x\)"):
        plan(column, ELASTIC, params, dt=2 * crit, transits=1)
    with pytest.warns(UserWarning, match="of member 0"):
        plan(column, ELASTIC, [params], dt=2 * crit, transits=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert plan(column, ELASTIC, params, dt=0.9 * crit, transits=1).dt == 0.9 * crit


def test_the_model_is_kept_for_the_same_sample_and_scene_by_content(column):
    """A scene with masks, and the same sample built again, find the first plan's model: no build."""
    from jaxbpm.dem import plan as plan_mod

    fixed, driven = ELASTIC.layers(column)
    masked = UniaxialCompression(strain=0.002, fixed=fixed, driven=driven)
    params = default_params(column)
    first = plan(column, masked, params, transits=10)
    builds = plan_mod._models.builds
    again = jaxbpm.generate.lattice("sc", (2, 2, 5), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})
    assert again is not column
    second = plan(again, UniaxialCompression(strain=0.002, fixed=fixed.copy(), driven=driven.copy()), params,
                  transits=10)
    assert plan_mod._models.builds == builds and second.model is first.model
    # the same masks as the layers give the same loading; other masks build a model of their own
    np.testing.assert_array_equal(np.asarray(second.load.clamped), np.asarray(plan(column, ELASTIC, params).load.clamped))
    fewer = driven.copy()
    fewer[np.flatnonzero(driven)[0]] = False
    other = UniaxialCompression(strain=0.002, fixed=fixed, driven=fewer)
    before = plan_mod._models.builds  # (the layered plan above may have built: the cache keeps the last four)
    plan(again, other, params, transits=10)
    assert plan_mod._models.builds == before + 1


def test_transit_time_of_touching_discs_is_that_of_the_linear_law():
    """Bond-free discs with linear contacts: mass and k_n = E* t both scale with the thickness, so the transit time
    is sqrt(m / k_n) per diameter crossed, with m = rho pi R^2 t, whatever t."""
    from jaxbpm.physics.model import build_model

    r, rho, emod = 1e-3, 2500.0, 1e9
    times = []
    for t in (1.0, 0.05):
        s = jaxbpm.Sample.from_arrays(np.array([[0.0, 0.0], [0.0, 2 * r]]), r, np.zeros((0, 2), int),
                                      bond_radius=np.zeros(0), thickness=t,
                                      particle_material={"E": emod, "nu": 0.25, "density": rho})
        model = build_model(s, contacts=True, contact_law=jaxbpm.physics.linear.LinearLaw(emod=emod))
        times.append(transit_time(s, model, default_params(s), 4 * r))
    np.testing.assert_allclose(times, 2 * np.sqrt(rho * np.pi * r**2 / emod), rtol=1e-12)
