"""Strict numerics for every test: float64, strict dtype promotion, no silent rank broadcasting."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import jax  # noqa: E402
import jax_md  # noqa: E402,F401  (jax-md's import-time code does not pass strict promotion: import it first)

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
jax.config.update("jax_numpy_rank_promotion", "raise")
