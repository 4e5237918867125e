"""One progress display for long work (packing, DEM runs): a tqdm bar on stderr.

Off by default in the library (``progress=True`` turns it on; a callable receives the raw numbers instead) and on in
the ``jaxbpm`` command. In a notebook with ipywidgets installed the bar is a widget (``tqdm.auto``), elsewhere text.
Messages that must stay (an attempt given up, a packing done) are printed above the bar, so they are never mixed
with it.
"""

from __future__ import annotations

import importlib.util
import sys

__all__ = ["bar", "say"]


def _tqdm():
    if importlib.util.find_spec("ipywidgets") is not None and "ipykernel" in sys.modules:
        from tqdm.auto import tqdm
    else:
        from tqdm.std import tqdm
    return tqdm


def bar(desc: str, total: int | None = None, unit: str = "step", leave: bool = True, disable: bool = False):
    """A progress bar on stderr.

    Update it with ``.update(n)``, set ``.set_postfix_str(...)`` for the quantity that tells how far the work is, and
    ``.close()`` it.

    Args:
      desc: the label in front of the bar.
      total: the count the bar fills up to (``None``: a counter with its rate).
      unit: the name of one counted item.
      leave: keep the finished bar on screen.
      disable: a bar that shows nothing (the same calls, no output).

    Returns:
      The ``tqdm`` bar (``tqdm.auto`` in a notebook with ipywidgets, text elsewhere).
    """
    return _tqdm()(total=total, desc=desc, unit=unit, file=sys.stderr, leave=leave, dynamic_ncols=True,
                   mininterval=0.5, smoothing=0.1, disable=disable)


def say(message: str) -> None:
    """Print ``message`` on its own line of stderr, above any open bar.

    Args:
      message: the text to print.
    """
    _tqdm().write(message, file=sys.stderr)
    sys.stderr.flush()
