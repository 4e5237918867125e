"""The scene protocol: what the scenes provide, the answers they share, and a scene written outside jaxbpm."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

import jaxbpm
from jaxbpm import SceneError
from jaxbpm.physics.loading import Loading
from jaxbpm.physics.model import build_model
from jaxbpm.scenes import (METHODS, AxialScene, BaseScene, BrazilianDisc, Scene, ThreePointBending,
                           UniaxialCompression, force_weights, lateral_stats, sample_breaks)

R = 1e-3
SCENES = (UniaxialCompression(), UniaxialCompression.to_failure(), ThreePointBending(), BrazilianDisc())


@pytest.fixture(scope="module")
def column():
    return jaxbpm.generate.lattice("sc", (2, 2, 6), R, bond_radius_ratio=0.5, materials={"E": 1e9, "nu": 0.25})


@dataclasses.dataclass(frozen=True)
class Squeeze:
    """A user's scene: the protocol's members, nothing of jaxbpm's scene classes (bottom and top layer of centres
    clamped along z, the top one moved down)."""

    strain: float = 0.002
    methods = ("dsm",)
    axis = 2
    fit_range = (0.25, 1.0)
    contacts = False
    breakage = False
    cohesive_law = None
    uses_walls = False
    wall_law = "hertz"
    wall_stiffness = None
    failure_rule = "separate"

    def layers(self, sample):
        z = np.asarray(sample.positions)[:, 2]
        return z == z.min(), z == z.max()

    def geometry(self, sample):
        fixed, driven = self.layers(sample)
        z = np.asarray(sample.positions)[:, 2]
        return float(z[driven].mean() - z[fixed].mean()), 16 * R**2

    def model(self, sample, **overrides):
        return build_model(sample, **{"contacts": False, "failure_rule": self.failure_rule, **overrides})

    def loading(self, sample, speed):
        fixed, driven = self.layers(sample)
        velocity = np.zeros((sample.n_particles, 3))
        velocity[driven, 2] = -speed
        none = jnp.zeros((0, 3))
        return Loading(clamped=jnp.asarray(fixed | driven), velocity=jnp.asarray(velocity), wall_points0=none,
                       wall_normals=none, wall_velocity=none)

    def compressive_force(self, reaction):
        return 0.5 * (reaction[:, 0, 2] - reaction[:, 1, 2])

    def fit_mask(self, displacement, target):
        return displacement >= self.fit_range[0] * target

    def fit_stiffness(self, displacement, force, target):
        sel = self.fit_mask(displacement, target)
        return float(np.polyfit(displacement[sel], force[sel], 1)[0])

    def modulus(self, stiffness, sample):
        length, area = self.geometry(sample)
        return stiffness * length / area

    def strength(self, peak_force, sample):
        return peak_force / self.geometry(sample)[1]

    def transit_length(self, sample):
        return self.geometry(sample)[0]

    def lateral_strain(self, sample, displacement):
        raise SceneError("no lateral strain")


def test_the_scenes_follow_the_protocol():
    for scene in SCENES:
        assert isinstance(scene, Scene), scene
        assert scene.methods and set(scene.methods) <= set(METHODS)
    assert isinstance(Squeeze(), Scene)
    assert not isinstance("uniaxial", Scene)

    class Partial:  # geometry and model alone are no scene
        def geometry(self, sample):
            return 1.0, 1.0

        def model(self, sample, **overrides):
            return None

    assert not isinstance(Partial(), Scene)
    assert (UniaxialCompression.methods, ThreePointBending.methods, BrazilianDisc.methods) == (
        ("dem", "dsm", "ste"), ("dem", "dsm"), ("dem",))
    with pytest.raises(jaxbpm.calibrate.CalibrationError, match="not a jaxbpm scene"):
        jaxbpm.calibrate.forward_model(jaxbpm.generate.lattice("sc", (2, 2, 3), R), Partial(), "dsm")


def test_arguments_and_repr_are_the_scenes_own():
    assert repr(UniaxialCompression(strain=0.002)) == (
        "UniaxialCompression(axis=2, strain=0.002, boundary='layers', fixed=None, driven=None, layer_thickness=None, "
        "gauge_length=None, area=None, contacts=False, rotations=None, wall_law='hertz', wall_stiffness=None, "
        "fit_range=(0.25, 1.0), breakage=None, contact_law='hertz', cohesive=None, failure_rule='separate', "
        "stop_after_peak=0.7)")
    assert repr(BrazilianDisc()) == (
        "BrazilianDisc(axis=0, disc_axis=2, strain=0.02, diameter=None, thickness=None, contacts=True, "
        "rotations=None, wall_law='hertz', wall_stiffness=None, fit_range=(0.05, 0.25), breakage=True, "
        "contact_law='hertz', cohesive=None, platens='strips', strip_width=None, layer_thickness=None, "
        "failure_rule='separate', stop_after_peak=0.7, "
        "fixed=None, driven=None)")
    for cls in (UniaxialCompression, BrazilianDisc):
        assert issubclass(cls, AxialScene)
        assert sorted(cls._FIELD_ORDER) == sorted(f.name for f in dataclasses.fields(cls))
        with pytest.raises(TypeError):
            cls(2)  # keyword arguments only
    assert not issubclass(ThreePointBending, AxialScene) and issubclass(ThreePointBending, BaseScene)
    scene = dataclasses.replace(BrazilianDisc(), platens="walls")
    assert scene.uses_walls and scene.boundary == "walls" and scene == BrazilianDisc(platens="walls")
    assert hash(scene) == hash(BrazilianDisc(platens="walls"))


def test_shared_answers(column):
    scene = UniaxialCompression()
    u = np.linspace(0.0, 1e-5, 11)
    # the fit reads the records within fit_range only: a line there, anything before
    force = np.where(u >= 0.25e-5, 3e6 * u + 1.0, 0.0)
    assert scene.fit_stiffness(u, force, 1e-5) == pytest.approx(3e6, rel=1e-9)
    np.testing.assert_array_equal(scene.fit_mask(u, 1e-5), u >= 0.25e-5 - 1e-20)
    with pytest.raises(SceneError, match="too few records"):
        scene.fit_stiffness(u[:3], force[:3], 1e-5)
    length, area = scene.geometry(column)
    assert scene.modulus(2.0, column) == pytest.approx(2.0 * 10 * R / (16 * R**2))
    assert scene.strength(4.0, column) == pytest.approx(4.0 / area)
    assert scene.transit_length(column) == length
    reaction = np.zeros((2, 2, 3))
    reaction[:, 0, 2], reaction[:, 1, 2] = 5.0, -3.0  # the fixed layer pushed down, the driven one up
    np.testing.assert_allclose(scene.compressive_force(reaction), 4.0)
    np.testing.assert_allclose(UniaxialCompression(boundary="walls").compressive_force(-reaction), 4.0)
    assert ThreePointBending().cohesive_law is None and BrazilianDisc().cohesive_law is None
    with pytest.raises(SceneError, match="ThreePointBending measures no lateral strain"):
        ThreePointBending().lateral_strain(column, np.zeros((column.n_particles, 3)))
    assert lateral_stats(ThreePointBending(), column, np.zeros((column.n_particles, 3))) == {}
    assert lateral_stats(scene, column, None) == {}


def test_sample_breaks_reads_the_strengths(column):
    assert not sample_breaks(column, None)  # no finite strength in the material table
    assert sample_breaks(column, True) and not sample_breaks(column, False)
    strong = column.replace(materials=dataclasses.replace(column.materials, tensile_strength=np.array([1e6])))
    assert sample_breaks(strong, None)


def test_a_scene_of_ones_own_is_solved_by_the_dsm(column):
    """The DSM serves any class that follows the protocol: the user's squeeze is the uniaxial compression between
    clamped layers, so the stiffness is the same; four chains of five bonds k_n = E A / d in series give 4 k_n / 5."""
    mine = jaxbpm.solve(column, Squeeze(), "dsm")
    ours = jaxbpm.solve(column, UniaxialCompression(strain=0.002), "dsm")
    assert mine.stiffness == pytest.approx(ours.stiffness, rel=1e-12)
    kn = 1e9 * np.pi * (0.5 * R) ** 2 / (2 * R)
    assert mine.stiffness == pytest.approx(4 * kn / 5, rel=1e-3)
    assert mine.poisson_ratio is None  # the scene measures no lateral strain
    for method in ("dem", "ste"):  # the solvers it does not list refuse it
        with pytest.raises(SceneError, match=f"Squeeze needs method='dsm': the {method.upper()} does not model it"):
            jaxbpm.solve(column, Squeeze(), method)


@pytest.mark.parametrize("scene, n_walls", [(UniaxialCompression(), 0), (UniaxialCompression(boundary="walls"), 2),
                                            (BrazilianDisc(), 0), (BrazilianDisc(platens="walls"), 2),
                                            (ThreePointBending(), 0), (Squeeze(), 0)])
def test_force_weights_make_the_scenes_force(scene, n_walls):
    """The weights a compiled run measures the force with give ``compressive_force`` of any reactions."""
    reaction = np.random.default_rng(1).standard_normal((5, n_walls + 2, 3))
    weights = force_weights(scene, n_walls + 2)
    np.testing.assert_allclose(np.einsum("krc,rc->k", reaction, weights), scene.compressive_force(reaction),
                               rtol=1e-13, atol=1e-13)


def test_a_force_not_linear_in_the_reactions_is_refused():
    @dataclasses.dataclass(frozen=True)
    class Crushed(Squeeze):
        def compressive_force(self, reaction):
            return np.abs(reaction[:, 0, 2])  # (a magnitude: not linear)

    with pytest.raises(SceneError, match="not a linear combination of the reactions.*stop_after_peak=None"):
        force_weights(Crushed(), 2)


@pytest.mark.parametrize("value", [0, 1, 1.5, -0.2, True, "0.7", float("nan")])
def test_stop_after_peak_out_of_range_is_refused(value):
    for cls in (UniaxialCompression, BrazilianDisc, ThreePointBending):
        with pytest.raises(SceneError, match=r"stop_after_peak must be a fraction of the peak force in \(0, 1\)"):
            cls(stop_after_peak=value)


def test_stop_after_peak_defaults_to_seven_tenths():
    for cls in (UniaxialCompression, BrazilianDisc, ThreePointBending):
        assert cls().stop_after_peak == 0.7 and cls(stop_after_peak=None).stop_after_peak is None
        assert cls(stop_after_peak=0.8) != cls()
    assert UniaxialCompression.to_failure(stop_after_peak=0.75).stop_after_peak == 0.75


def test_linear_contact_law_on_every_scene(column):
    """contact_law="linear" (or a LinearLaw) on each scene: its model runs the linear law (also the contact-free
    model a static solve starts from, whose contacts it switches on later), contacts required."""
    from jaxbpm.physics.linear import LinearLaw, LinearParams

    law = LinearLaw(emod=3e9, kratio=1.21)
    for scene in (UniaxialCompression(contacts=True, contact_law="linear"), BrazilianDisc(contact_law=law),
                  ThreePointBending(contact_law="linear")):
        assert scene.cohesive_law is None and isinstance(scene.linear_law, LinearLaw)
        for model in (scene.model(column), scene.model(column, contacts=False)):
            assert model.contact_law == "linear" and isinstance(model.contact, LinearParams)
    assert float(BrazilianDisc(contact_law=law).model(column).contact.emod) == 3e9
    assert UniaxialCompression(contacts=True).model(column).contact_law == "hertz"
    assert ThreePointBending().linear_law is None
    with pytest.raises(SceneError, match="contact_law='linear' needs contacts=True"):
        UniaxialCompression(contact_law="linear")
    with pytest.raises(SceneError, match="contact_law='linear' needs contacts=True"):
        ThreePointBending(contacts=False, contact_law=law)
    with pytest.raises(SceneError, match="not the cohesive law"):
        ThreePointBending(contact_law="cohesive")
    with pytest.raises(SceneError, match="cohesive contact parameters were given with contact_law='linear'"):
        UniaxialCompression(contacts=True, contact_law="linear", cohesive={"c0": 1.0})
    with pytest.raises(SceneError, match="unknown contact law"):
        BrazilianDisc(contact_law="Linear")
