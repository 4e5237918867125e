"""Compile once: size classes, padding that changes no result, and solves that compile nothing the second time."""

import collections
import dataclasses
import os

import jax
import numpy as np
import pytest

import jaxbpm
from jaxbpm import _compile, dsm, ste
from jaxbpm._compile import content_key, Program, SetupCache, capacity, count_compilations, size_class
from jaxbpm.physics.model import default_params
from jaxbpm.scenes import UniaxialCompression

# one xdist worker for the module: `packing` (a 400-particle box, ~10 s to make) is built once, and the tests that
# solve it share their compiled programs
pytestmark = pytest.mark.xdist_group("compile-module")

R = 1e-3
MATERIALS = {"E": 1e9, "nu": 0.25}
SCENE = UniaxialCompression(strain=0.002)


@pytest.fixture(scope="module")
def packing():
    return jaxbpm.generate.box(400, seed=5, mean_radius=R, materials=MATERIALS).largest_cluster()


def _lattice(cells):
    return jaxbpm.generate.lattice("sc", cells, R, bond_radius_ratio=0.5, materials=MATERIALS)


def test_capacity_ladder():
    for count in [1, 7, 8, 9, 100, 2500, 3000, 3500, 4096, 4097, 10 ** 6]:
        cap = capacity(count)
        assert cap >= count
        assert cap <= max(8, 1.25 * count + 1)  # at most 25 % padding
        mantissa = cap / 2 ** (cap.bit_length() - 3)
        assert mantissa in (4, 5, 6, 7, 8)
    # the example: 2500..3500 particles fall in three classes
    assert len({size_class(n, int(3.2 * n)).particles for n in range(2500, 3501)}) == 3


def test_size_class_has_room_for_padding():
    for n, nb in [(10, 0), (127, 300), (128, 400), (2999, 9509)]:
        c = size_class(n, nb)
        assert c.particles >= n + 2 and c.bonds >= nb + (1 if nb else 0)


def test_samples_of_one_generator_fall_in_three_classes(monkeypatch):
    # 20 samples with 2500..3500 particles and ~3.0-3.2 bonds per particle (a box packing's): the three particle
    # capacities of that range, one bond capacity each, although the bond counts straddle steps of the ladder
    monkeypatch.setattr(_compile, "_classes", collections.defaultdict(set))
    rng = np.random.default_rng(0)
    n = rng.integers(2500, 3501, 20)
    nb = (n * rng.uniform(2.99, 3.2, 20)).astype(int)
    classes = {size_class(a, b) for a, b in zip(n, nb)}
    assert len(classes) == 3 and len({c.particles for c in classes}) == 3
    for a, b in zip(n, nb):
        c = size_class(a, b)
        assert c in classes and c.bonds > b and c.bonds <= c.particles * 3.5
    # a sample whose own class would be larger still reuses a handed-out one that has room for it
    low, high = size_class(2541, 7612), size_class(2516, int(2516 * 3.21))
    assert low == high and _compile._per_particle(int(2516 * 3.21), 2516, low.particles) > low.bonds
    # ...but not one much larger than its own
    assert size_class(2541, 2541 * 2).bonds < low.bonds


def test_program_compiles_once_per_signature():
    calls = []

    def fn(x, k):
        calls.append(1)  # traced once per compilation
        return x * k

    prog = Program(fn, static_argnames=("k",))
    out, ct, rt = prog(np.ones(3), k=2)
    np.testing.assert_array_equal(out, 2.0)
    assert prog.compilations == 1 and ct > 0 and rt >= 0
    out, ct, _ = prog(np.full(3, 2.0), k=2)
    np.testing.assert_array_equal(out, 4.0)
    assert prog.compilations == 1 and ct == 0.0
    prog(np.ones(4), k=2)   # new shape
    prog(np.ones(3), k=3)   # new static option
    assert prog.compilations == 3 and len(calls) == 3
    with pytest.raises(TypeError, match="unknown static options"):
        prog(np.ones(3), kk=1)


@pytest.mark.skipif(not os.path.exists("/proc/self/maps"), reason="memory mappings are read from Linux's /proc")
def test_release_executables_gives_back_their_memory_mappings():
    """Executables hold memory mappings (a process has at most vm.max_map_count of them); released, they are gone,
    and a program compiles again on its next call."""
    prog = Program(lambda x, k: jax.numpy.sin(x * k) @ jax.numpy.cos(x.T + k), static_argnames=("k",))
    _compile.release_executables()
    before = _compile.memory_mappings()
    for k in range(20):
        prog(np.ones((4, 4)), k=k)
    grown = _compile.memory_mappings()
    assert prog.compilations == 20 and grown > before + 20
    _compile.release_executables()
    assert _compile.memory_mappings() < before + (grown - before) / 4
    prog(np.ones((4, 4)), k=0)
    assert prog.compilations == 21


def test_priming_stops_after_a_long_execution(monkeypatch):
    """``prime=k`` runs a new executable k times (page faults of ms-long programs), but stops after one execution
    longer than the limit, and does not prime at all on arguments of more bytes than its limit (a large sample's
    run)."""
    runs = []

    def fn(x):
        jax.debug.callback(lambda: runs.append(1))
        return x + 1.0

    prog = Program(fn, prime=3)
    prog(np.ones(2))
    assert len(runs) == 3 + 1  # three primed executions and the call's own
    monkeypatch.setattr(_compile, "_PRIME_LIMIT", -1.0)  # every execution counts as long
    prog(np.ones(3))  # a new signature
    assert len(runs) == 4 + 1 + 1
    monkeypatch.setattr(_compile, "_PRIME_LIMIT", 1e9)
    monkeypatch.setattr(_compile, "_PRIME_BYTES", 8 * 4 - 1)  # arguments of more bytes are not primed at all
    prog(np.ones(4))
    assert len(runs) == 6 + 1
    prog(np.ones(2, np.float32).reshape(1, 2))  # 8 bytes: primed three times
    assert len(runs) == 7 + 3 + 1


def test_setup_programs_compile_quick_when_small(packing, monkeypatch):
    """A setup program (run once per sample) compiles with XLA's quick settings when its arguments are small, with the
    full optimisation when they are large or when it is traced inside another program; a DSM solve whose setup
    programs compiled either way gives the same answer."""
    prog = _compile.setup_jit(lambda x: 2.0 * x)
    small, large = np.ones((8, 3)), np.ones((_compile.QUICK_ROWS + 1, 3))
    assert prog.quick(small) and not prog.quick(large)
    np.testing.assert_array_equal(prog(small), 2.0)
    assert (prog._quick._cache_size(), prog._full._cache_size()) == (1, 0)
    np.testing.assert_array_equal(prog(large), 2.0)
    assert (prog._quick._cache_size(), prog._full._cache_size()) == (1, 1)
    inside = []
    np.testing.assert_array_equal(jax.jit(lambda x: inside.append(prog.quick(x)) or prog(x))(small), 2.0)
    assert inside == [False]
    a = jaxbpm.solve(packing, SCENE, method="dsm")
    dsm.linear._linear_setups.clear()
    monkeypatch.setattr(_compile, "QUICK_ROWS", 0)  # every setup program fully optimised
    assert not prog.quick(small)
    b = jaxbpm.solve(packing, SCENE, method="dsm")
    np.testing.assert_allclose(b.stiffness, a.stiffness, rtol=1e-12)


def test_setup_cache_is_per_object_and_bounded():
    class Owner:
        pass

    cache, a, b = SetupCache(maxsize=2), Owner(), Owner()
    assert cache.get(a, "k", lambda: 1) == 1
    assert cache.get(a, "k", lambda: 2) == 1          # hit
    assert cache.get(b, "k", lambda: 3) == 3          # another object
    assert cache.get(a, ("k", np.zeros(2).tobytes()), lambda: 4) == 4
    assert cache.get(b, "k", lambda: 5) == 3          # still there
    assert cache.get(a, "k", lambda: 5) == 5          # the oldest entry was dropped (maxsize 2)
    assert cache.get(a, ["mask", np.zeros(3, bool)], lambda: 6) == 6
    assert cache.get(a, ["mask", np.zeros(3, bool)], lambda: 7) == 6  # an equal array (a new object): by content
    assert cache.get(a, ["mask", np.ones(3, bool)], lambda: 8) == 8
    assert cache.get(a, ["mask", np.zeros(3, np.int8)], lambda: 9) == 9  # the same bytes, another dtype

    class NoContent:
        __hash__ = None

    assert cache.get(a, [NoContent()], lambda: 10) == 10
    assert cache.get(a, [NoContent()], lambda: 11) == 11  # nothing to key by: never cached


def test_content_key_of_scenes_with_masks():
    n = 10
    fixed, driven = np.arange(n) < 3, np.arange(n) >= 7
    a = UniaxialCompression(fixed=fixed, driven=driven)
    b = UniaxialCompression(fixed=fixed.copy(), driven=driven.copy())
    assert content_key(a) == content_key(b) and hash(content_key(a)) == hash(content_key(b))
    assert content_key(a) != content_key(UniaxialCompression(fixed=driven, driven=fixed))
    assert content_key(a) != content_key(UniaxialCompression(fixed=fixed, driven=driven, strain=0.003))
    assert content_key({"x": [1, np.ones(2)]}) == content_key({"x": [1, np.ones(2)]})
    assert content_key({"x": [1, object.__new__(type("NoHash", (), {"__hash__": None}))]}) is None


@pytest.mark.parametrize("method", ["ste", "dsm"])
def test_the_same_sample_loaded_again_keeps_its_setup(packing, method, tmp_path):
    # a new Sample object with the same arrays (the file loaded again) is known by its content: nothing is built
    jaxbpm.io.save_sample(tmp_path / "s.h5", packing)
    again = jaxbpm.io.load_sample(tmp_path / "s.h5")
    assert again is not packing
    setups = {"dsm": jaxbpm.dsm.linear._linear_setups, "ste": jaxbpm.ste.scene._setups}[method]
    first = jaxbpm.solve(packing, SCENE, method=method)
    built = setups.builds
    with count_compilations() as n:
        second = jaxbpm.solve(again, SCENE, method=method)
    assert setups.builds == built and n[0] == 0 and second.stiffness == first.stiffness
    moved = again.replace(positions=np.asarray(again.positions) * (1 + 1e-9))  # other content: built again
    jaxbpm.solve(moved, SCENE, method=method)
    assert setups.builds == built + 1


@pytest.mark.parametrize("method", ["ste", "dsm"])
def test_a_scene_with_masks_keeps_its_setup(packing, method):
    # the clamped particles given as masks: a second solve, with a new but equal scene, builds and compiles nothing
    z = np.asarray(packing.positions)[:, 2]
    fixed, driven = z <= z.min() + 1.5e-3, z >= z.max() - 1.5e-3
    setups = {"dsm": jaxbpm.dsm.linear._linear_setups, "ste": jaxbpm.ste.scene._setups}[method]
    first = jaxbpm.solve(packing, UniaxialCompression(fixed=fixed, driven=driven), method=method)
    built = setups.builds
    with count_compilations() as n:
        again = jaxbpm.solve(packing, UniaxialCompression(fixed=fixed.copy(), driven=driven.copy()), method=method)
    assert setups.builds == built and n[0] == 0
    assert again.stiffness == first.stiffness


@pytest.mark.parametrize("options", [{}, {"dofs": 6}, {"layered": True}, {"first_neighbour": True},
                                     {"precision": "float32"}])
def test_ste_padding_changes_nothing(packing, options):
    a = jaxbpm.solve(packing, SCENE, method="ste", pad=False, **options)
    b = jaxbpm.solve(packing, SCENE, method="ste", pad=True, **options)
    assert b.stats["size_class"][0] > packing.n_particles and b.stats["size_class"][1] > packing.n_bonds
    assert a.stats["size_class"] == [packing.n_particles, packing.n_bonds, 0]
    tol = 1e-5 if options.get("precision") == "float32" else 1e-12
    np.testing.assert_allclose(b.stiffness, a.stiffness, rtol=tol)
    np.testing.assert_allclose(b.stats["tensor"], a.stats["tensor"], rtol=tol, atol=tol * np.max(a.stats["tensor"]))
    for key in ("skipped", "surface", "particles", "bonds", "contacts"):
        assert a.stats[key] == b.stats[key]


def test_ste_padding_with_walls_and_contacts(packing):
    scene = UniaxialCompression(strain=0.002, boundary="walls", contacts=True)
    a = jaxbpm.solve(packing, scene, method="ste", pad=False)
    b = jaxbpm.solve(packing, scene, method="ste", pad=True)
    assert a.stats["contacts"] > 0 and b.stats["size_class"][2] > a.stats["contacts"]
    np.testing.assert_allclose(b.stiffness, a.stiffness, rtol=1e-12)
    for key in ("k_bottom", "k_top"):
        np.testing.assert_allclose(b.stats[key], a.stats[key], rtol=1e-12)
    assert (a.stats["n_bottom"], a.stats["n_top"]) == (b.stats["n_bottom"], b.stats["n_top"])


def test_ste_local_tensors_of_padded_estimator(packing):
    p = default_params(packing)
    a = np.asarray(ste.local_tensors(ste.estimator(packing), p))
    b = np.asarray(ste.local_tensors(ste.estimator(packing, pad=True), p))
    n = packing.n_particles
    np.testing.assert_allclose(b[:n], a, rtol=1e-12, atol=1e-12 * np.nanmax(np.abs(a)))
    assert np.all(np.isnan(b[n:]))  # the padding is singular


def test_dsm_padding_changes_nothing(packing):
    a = jaxbpm.solve(packing, SCENE, method="dsm", pad=False)
    b = jaxbpm.solve(packing, SCENE, method="dsm", pad=True)
    assert b.stats["size_class"][0] > packing.n_particles
    np.testing.assert_allclose(b.stiffness, a.stiffness, rtol=1e-12)
    np.testing.assert_allclose(b.stats["stiffness_boundary"], a.stats["stiffness_boundary"], rtol=1e-9)
    assert b.state.shape == a.state.shape
    np.testing.assert_allclose(b.state, a.state, rtol=0, atol=1e-9 * np.max(np.abs(a.state)))
    assert abs(a.stats["iterations"] - b.stats["iterations"]) <= 1
    np.testing.assert_allclose(b.stats["bond_forces"].normal, a.stats["bond_forces"].normal, rtol=0,
                               atol=1e-8 * np.max(np.abs(a.stats["bond_forces"].normal)))


@pytest.mark.parametrize("method", ["ste", "dsm"])
def test_gradient_through_padding(packing, method):
    p = {"bond_E": np.array([1.3e9]), "bond_nu": np.array([0.2])}
    module = {"ste": ste, "dsm": dsm}[method]
    options = {"ste": jaxbpm.STE, "dsm": lambda **o: jaxbpm.DSM(linear_tol=1e-10, **o)}[method]
    ga = jax.jit(jax.grad(module.stiffness_function(packing, SCENE, options(pad=False))))(p)
    gb = jax.jit(jax.grad(module.stiffness_function(packing, SCENE, options(pad=True))))(p)
    for key in ("bond_E", "bond_nu"):
        np.testing.assert_allclose(gb[key], ga[key], rtol=1e-9)
    assert float(ga["bond_E"][0]) > 0


@pytest.mark.parametrize("method", ["ste", "dsm"])
def test_second_solve_compiles_nothing(packing, method):
    jaxbpm.solve(packing, SCENE, method=method)
    with count_compilations() as n:
        r = jaxbpm.solve(packing, SCENE, method=method, params={"bond_E": np.array([2e9]),
                                                                  "bond_nu": np.array([0.3])})
    assert n[0] == 0 and r.compile_time == 0.0
    assert r.wall_time == pytest.approx(r.setup_time + r.compile_time + r.run_time, rel=1e-9)


@pytest.mark.parametrize("method", ["ste", "dsm"])
def test_one_size_class_shares_its_program(method):
    a, b = _lattice((4, 4, 8)), _lattice((4, 5, 7))
    assert a.n_particles != b.n_particles and a.n_bonds != b.n_bonds
    assert size_class(a.n_particles, a.n_bonds) == size_class(b.n_particles, b.n_bonds)
    program = {"ste": ste.scene.solve_program, "dsm": dsm.linear.linear_program}[method]
    ra = jaxbpm.solve(a, SCENE, method=method)
    before = program.compilations
    rb = jaxbpm.solve(b, SCENE, method=method)
    assert program.compilations == before and rb.compile_time == 0.0
    assert ra.stats["size_class"] == rb.stats["size_class"]
    # and the answers are each sample's own (the closed form of a simple cubic column: k_n per column)
    assert rb.stiffness != ra.stiffness


def test_linearised_contact_candidates_are_padded(packing, monkeypatch):
    # the linear DSM with linearised contacts pads its candidates (a far-apart pair that never touches): the same
    # answer, and another reach with about as many candidates runs the same compiled program
    s = packing.replace(particle_material=dataclasses.replace(packing.particle_material, E=5e9))
    scene = UniaxialCompression(strain=0.002, contacts=True)
    model = scene.model(s)
    r = float(np.mean(s.radii))
    skins = [r * f for f in np.linspace(0.02, 0.2, 10)]
    counts = [len(dsm.contact_candidates(s, model, k)) for k in skins]
    k1, k2 = next((skins[i], skins[i + 1]) for i in range(len(skins) - 1)
                  if counts[i] != counts[i + 1] and capacity(counts[i] + 1) == capacity(counts[i + 1] + 1))
    a = jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_skin=k1)
    with monkeypatch.context() as m:
        m.setattr(dsm.scene, "pad_candidates", lambda lin, sample, axis: lin)
        b = jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_skin=k1)
    assert a.stats["contacts_touching"] > 0
    np.testing.assert_allclose(a.stiffness, b.stiffness, rtol=1e-12)
    before = dsm.linear.contacts_program.compilations
    c = jaxbpm.solve(s, scene, method="dsm", nonlinear=False, contact_skin=k2)
    assert c.stats["contact_candidates"] != a.stats["contact_candidates"]
    assert dsm.linear.contacts_program.compilations == before and c.compile_time == 0.0


def test_quick_options_are_those_the_compiler_knows(monkeypatch):
    # jaxlib 0.11 dropped xla_cpu_use_fusion_emitters: an option the compiler does not know must be left out, not
    # fail every setup program
    known = _compile.quick_options()
    assert known and set(known) <= set(_compile.QUICK_OPTIONS)
    assert known["xla_backend_optimization_level"] == 0
    monkeypatch.setattr(_compile, "_quick_options", None)
    monkeypatch.setattr(_compile, "QUICK_OPTIONS", {**_compile.QUICK_OPTIONS, "xla_no_such_option": True})
    assert "xla_no_such_option" not in _compile.quick_options()
    square = _compile.setup_jit(lambda x: x * x)
    np.testing.assert_allclose(square(np.arange(3.0)), [0.0, 1.0, 4.0])
