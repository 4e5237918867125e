"""Values shown in error messages: plain numbers, shortened; used by the data types, the options and the records."""

from __future__ import annotations

import numpy as np

__all__ = ["shown"]


def shown(value, limit: int = 80) -> str:
    """``value`` for an error message: plain numbers (``1.5``, ``[1.0, 2.0]``, not NumPy reprs), shortened.

    Args:
      value: anything; NumPy arrays and scalars are shown as their ``tolist()``.
      limit: the longest text returned; longer reprs end in ``...``.

    Returns:
      The repr of ``value`` (or ``a <type name>`` when its repr fails), at most ``limit`` characters.
    """
    try:
        if isinstance(value, (np.ndarray, np.generic)):
            value = value.tolist()
        text = repr(value)
    except Exception:  # noqa: BLE001 (a value whose repr fails still gets a message)
        text = f"a {type(value).__name__}"
    return text if len(text) <= limit else text[:limit - 3] + "..."
