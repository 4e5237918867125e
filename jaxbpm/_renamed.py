"""Keywords under their new names, with the old names still accepted for one release."""

from __future__ import annotations

import warnings

__all__ = ["batch_size_keyword"]


def batch_size_keyword(batch_size, chunk, *, stacklevel: int = 3):
    """The number of parameter sets evaluated at once, given as ``batch_size=`` or its deprecated name ``chunk=``.

    Args:
      batch_size: the value given as ``batch_size`` (``None``: not given).
      chunk: the value given as ``chunk`` (``None``: not given).
      stacklevel: the frame the warning names (3: the caller of the function that calls this one).

    Returns:
      ``batch_size``, or ``chunk`` where only that was given (with a :class:`DeprecationWarning` naming
      ``batch_size=``).

    Raises:
      TypeError: both were given.
    """
    if chunk is None:
        return batch_size
    if batch_size is not None:
        raise TypeError("give batch_size= only (chunk= is its deprecated name)")
    warnings.warn("chunk= is deprecated and will be removed in the next release; use batch_size= (the same value)",
                  DeprecationWarning, stacklevel=stacklevel)
    return chunk
