"""Small functions the force laws share, which work on ``(x, y, z)`` tuples of component arrays (one array per
component, so that XLA keeps every intermediate a flat ``[P]`` array): dot and cross products, a square root with a
finite derivative at zero, and the conversion of a law's component tuples to ``[..., 3]`` arrays.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["dot", "cross", "safe_sqrt", "once", "stack"]


def dot(a, b):
    """The dot product of two component tuples.

    Args:
        a: ``(x, y, z)``, scalars or equal-shape arrays.
        b: the same.

    Returns:
        ``a . b``, shaped as the components.
    """
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    """The cross product of two component tuples.

    Args:
        a: ``(x, y, z)``, scalars or equal-shape arrays.
        b: the same.

    Returns:
        ``a x b``, an ``(x, y, z)`` tuple.
    """
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


def safe_sqrt(x):
    """A square root whose derivative is 0 (not inf or NaN) at zero.

    Args:
        x: an array, ``x >= 0``.

    Returns:
        ``sqrt(x)``.
    """
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def once(a, one):
    """``a`` divided by a run-time one, so that XLA computes it once instead of in each consumer.

    Args:
        a: an array.
        one: a run-time 1.0 (XLA cannot fold it away).

    Returns:
        ``a / one``, equal to ``a``.
    """
    return a / one


def stack(out):
    """Stack the component tuples of a named tuple into arrays.

    Args:
        out: a named tuple whose fields are ``(x, y, z)`` component tuples or arrays.

    Returns:
        The same named tuple with each component tuple stacked into a ``[..., 3]`` array, other fields as they are.
    """
    return type(out)(*(jnp.stack(o, axis=-1) if isinstance(o, tuple) else o for o in out))
