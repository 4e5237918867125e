"""What the calibration tests share: the scene, a solve of a sample's modulus and a cheap analytic forward."""

import importlib

import jax.numpy as jnp

import jaxbpm
from jaxbpm.calibrate import Forward, Parameter, ParameterSpace, Problem
from jaxbpm.scenes import UniaxialCompression

SCENE = UniaxialCompression(strain=0.002)
SOLVE = importlib.import_module("jaxbpm.solving")


def _modulus(sample, params):
    return jaxbpm.solve(sample, SCENE, "dsm", params=params).youngs_modulus


def _analytic(c=3.0):
    """A cheap homogeneous model: E = c * bond_E, K = 2 c * bond_E[1] + 0.01 bond_E[0]."""
    def fn(params):
        e = params["bond_E"]
        return {"youngs_modulus": c * e[0], "stiffness": 2 * c * e[1] + 0.01 * e[0]}
    return Forward.from_function(fn, name="analytic")


def _analytic_problem(targets, n=1, **space_kw):
    base = {"bond_E": jnp.array([1.0, 1.0]), "bond_nu": jnp.array([0.3, 0.3])}
    params = [Parameter("bond_E", i, bounds=(1e-3, 1e3)) for i in range(n)]
    return Problem(_analytic(), targets, ParameterSpace(params, base, **space_kw))

