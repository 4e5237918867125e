"""Small helpers of the force laws, which work on ``(x, y, z)`` tuples of component arrays (one array per component,
so that XLA keeps every intermediate a flat ``[P]`` array): dot and cross products, a square root with a finite
derivative at zero, and the conversion of a law's component tuples to ``[..., 3]`` arrays.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["dot", "cross", "safe_sqrt", "once", "stack"]


def dot(a, b):
    """``a . b`` of two component tuples."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    """``a x b`` of two component tuples, as a component tuple."""
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


def safe_sqrt(x):
    """``sqrt(x)`` for ``x >= 0`` whose derivative is 0 (not inf or NaN) where ``x == 0``."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def once(a, one):
    """``a`` itself, divided by the run-time ``one``: XLA computes it once instead of in each consumer."""
    return a / one


def stack(out):
    """A named tuple of component tuples (and scalars) as the same named tuple of ``[..., 3]`` arrays."""
    return type(out)(*(jnp.stack(o, axis=-1) if isinstance(o, tuple) else o for o in out))
