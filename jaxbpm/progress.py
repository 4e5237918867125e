"""One progress display for long work (packing, DEM runs): a tqdm bar on stderr, or lines where stderr is a file.

Off by default in the library (``progress=True`` turns it on; a callable receives the raw numbers instead) and on in
the ``jaxbpm`` command. In a notebook with ipywidgets installed the bar is a widget (``tqdm.auto``); on a terminal,
text redrawn in place; where stderr is not a terminal (a log file, a pipe, a batch job) a line every tenth of the work
(or every :data:`LINE_INTERVAL` seconds without a total), so that a log reads line by line instead of one line of
carriage returns. Messages that must stay (an attempt given up, a packing done) are printed above the bar, so they
are never mixed with it.
"""

from __future__ import annotations

import importlib.util
import sys
import time

__all__ = ["bar", "say", "Lines", "LINE_INTERVAL"]

#: the seconds between two lines of a progress written as lines without a total
LINE_INTERVAL = 10.0


def _in_kernel() -> bool:
    """Whether this code runs in a Jupyter kernel (not merely in a process that imported ipykernel, as a notebook
    runner does)."""
    ipython = sys.modules.get("IPython")
    shell = getattr(ipython, "get_ipython", lambda: None)() if ipython is not None else None
    return shell is not None and type(shell).__name__ == "ZMQInteractiveShell"


def _tqdm():
    if importlib.util.find_spec("ipywidgets") is not None and _in_kernel():
        from tqdm.auto import tqdm
    else:
        from tqdm.std import tqdm
    return tqdm


def bar(desc: str, total: int | None = None, unit: str = "step", leave: bool = True, disable: bool = False,
        lines: bool | None = None):
    """A progress bar on stderr.

    Update it with ``.update(n)``, set ``.set_postfix_str(...)`` for the quantity that tells how far the work is, and
    ``.close()`` it.

    Args:
      desc: the label in front of the bar.
      total: the count the bar fills up to (``None``: a counter with its rate).
      unit: the name of one counted item.
      leave: keep the finished bar on screen (lines: write a last line at the close).
      disable: a bar that shows nothing (the same calls, no output).
      lines: write lines instead of a bar redrawn in place (``None``: where stderr is not a terminal and not a
        notebook).

    Returns:
      The ``tqdm`` bar (``tqdm.auto`` in a notebook with ipywidgets, text elsewhere), or a :class:`Lines` progress.
    """
    if lines is None:
        isatty = getattr(sys.stderr, "isatty", lambda: False)
        lines = not isatty() and not _in_kernel()
    if lines:
        return Lines(desc, total=total, unit=unit, leave=leave, disable=disable)
    return _tqdm()(total=total, desc=desc, unit=unit, file=sys.stderr, leave=leave, dynamic_ncols=True,
                   mininterval=0.5, smoothing=0.1, disable=disable)


class Lines:
    """Progress written as lines on stderr: one when a tenth of ``total`` more is done (without a total, every
    :data:`LINE_INTERVAL` seconds) and one at the close; the calls of a ``tqdm`` bar that jaxbpm uses (``update``,
    ``set_postfix_str``, ``close``, ``n``)."""

    def __init__(self, desc: str, total: int | None = None, unit: str = "step", leave: bool = True,
                 disable: bool = False):
        self.desc, self.total, self.unit, self.leave, self.disable = desc, total, unit, leave, disable
        self.n, self.postfix, self._t0 = 0, "", time.perf_counter()
        self._shown, self._last, self._closed = -1, self._t0, False

    def update(self, n: int = 1) -> None:
        """Count ``n`` more; write a line where a tenth more of the work (or :data:`LINE_INTERVAL` s) has passed."""
        self.n += n
        now = time.perf_counter()
        if self.total:
            tenth = int(10 * self.n / self.total)
            if tenth > self._shown and self.n < self.total:
                self._shown = tenth
                self._write()
        elif now - self._last >= LINE_INTERVAL:
            self._last = now
            self._write()

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        """The quantity written after the count (``refresh`` is accepted and ignored: lines are written by
        :meth:`update`)."""
        self.postfix = str(s)

    def close(self) -> None:
        """Write the last line (with ``leave``), once."""
        if not self._closed and self.leave:
            self._write()
        self._closed = True

    def line(self) -> str:
        """The progress as one line of text."""
        elapsed = time.perf_counter() - self._t0
        count = (f"{100 * self.n / self.total:3.0f}% {self.n}/{self.total} {self.unit}" if self.total
                 else f"{self.n} {self.unit}")
        return f"{self.desc}: {count}, {elapsed:.1f} s" + (f", {self.postfix}" if self.postfix else "")

    def _write(self) -> None:
        if not self.disable:
            print(self.line(), file=sys.stderr, flush=True)


def say(message: str) -> None:
    """Print ``message`` on its own line of stderr, above any open bar.

    Args:
      message: the text to print.
    """
    _tqdm().write(message, file=sys.stderr)
    sys.stderr.flush()
