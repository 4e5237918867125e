"""Sharded parameter sweeps: the same answers on one device and on two (host platform split in two)."""

import json
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxbpm import sweep


def _model(p):
    return {"k": p["E"] * jnp.sum(p["w"] ** 2), "g": jnp.sin(p["E"]) * p["w"]}


def _batch(n):
    rng = np.random.default_rng(0)
    return {"E": jnp.asarray(rng.uniform(1, 2, n)), "w": jnp.asarray(rng.normal(size=(n, 3)))}


@pytest.mark.parametrize("n, batch_size", [(7, None), (8, 3), (1, None)])
def test_sweep_equals_vmap_on_one_device(n, batch_size):
    batch = _batch(n)
    out = sweep.sweep(_model, batch, batch_size=batch_size)
    ref = jax.vmap(_model)(batch)
    np.testing.assert_allclose(out["k"], ref["k"], rtol=1e-14)
    np.testing.assert_allclose(out["g"], ref["g"], rtol=1e-14)
    assert out["k"].shape == (n,)


def test_bad_batches_are_named():
    with pytest.raises(ValueError, match="same leading"):
        sweep.sweep(_model, {"E": jnp.ones(3), "w": jnp.ones((4, 3))})
    with pytest.raises(ValueError, match="scalar"):
        sweep.sweep(_model, {"E": jnp.ones(()), "w": jnp.ones((4, 3))})
    with pytest.raises(ValueError, match="batch_size"):
        sweep.sweep(_model, _batch(3), batch_size=0)


def test_chunk_is_a_deprecated_name_of_batch_size():
    batch = _batch(8)
    new = sweep.sweep(_model, batch, batch_size=3)
    with pytest.warns(DeprecationWarning, match="batch_size="):
        old = sweep.sweep(_model, batch, chunk=3)
    np.testing.assert_array_equal(old["k"], new["k"])
    np.testing.assert_array_equal(old["g"], new["g"])
    with pytest.raises(TypeError, match="batch_size= only"):
        sweep.sweep(_model, batch, batch_size=3, chunk=3)


def test_sweep_over_two_host_devices_matches_the_unsharded_result(tmp_path):
    # a fresh process: the device count is fixed when JAX starts
    script = tmp_path / "two.py"
    script.write_text(textwrap.dedent("""
        import json, sys
        import jax
        jax.config.update("jax_enable_x64", True)
        import jax.numpy as jnp, numpy as np
        import jaxbpm
        from jaxbpm import sweep, dsm
        from jaxbpm.scenes import UniaxialCompression
        assert len(jax.devices()) == 2, jax.devices()
        s = jaxbpm.generate.lattice("sc", (3, 3, 5), 1e-3, materials={"E": [1e9, 2e9], "nu": 0.25})
        s = jaxbpm.generate.mix_materials(s, [0.5, 0.5], seed=0)
        f = dsm.stiffness_function(s, UniaxialCompression(strain=0.002))
        E = np.stack([np.linspace(1e9, 3e9, 5), np.linspace(2e9, 1e9, 5)], axis=1)
        batch = {"bond_E": jnp.asarray(E), "bond_nu": jnp.full((5, 2), 0.25)}
        sharded = sweep.sweep(f, batch)
        plain = jax.vmap(f)(batch)
        single = [float(f({"bond_E": jnp.asarray(e), "bond_nu": jnp.full(2, 0.25)})) for e in E]
        # the calibrators' batches (surrogate run sets, finite-difference points) go through the same sharding
        from jaxbpm import calibrate as cal
        obj = cal.Problem(cal.forward_model(s, UniaxialCompression(strain=0.002)),
                          [cal.Target("stiffness", 1.0)],
                          cal.ParameterSpace([cal.Parameter("bond_E", index=0), cal.Parameter("bond_E", index=1)],
                                             cal.base_params(s)))
        calib = obj.outputs(E)[:, 0]
        print(json.dumps({"sharded": np.asarray(sharded).tolist(), "plain": np.asarray(plain).tolist(),
                          "single": single, "calibrate": np.asarray(calib).tolist()}))
    """))
    # (the suite's XLA flags kept: they make compilation cheaper)
    flags = (os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2").strip()
    env = {**os.environ, "XLA_FLAGS": flags, "JAX_PLATFORMS": "cpu"}
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    out = json.loads(run.stdout.strip().splitlines()[-1])
    np.testing.assert_allclose(out["sharded"], out["plain"], rtol=1e-12)
    np.testing.assert_allclose(out["sharded"], out["single"], rtol=1e-9)
    np.testing.assert_allclose(out["calibrate"], out["single"], rtol=1e-9)
    assert len(set(np.round(out["sharded"], 3))) == 5  # five different stiffnesses
