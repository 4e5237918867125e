"""The progress display: the bar's text on stderr (read from pytest's captured stream), a counter without a total, a
disabled bar writing nothing, and messages printed on a line of their own above an open bar."""

import re

from jaxbpm import progress


def _lines(text: str) -> list[str]:
    return [part.strip() for part in re.split(r"[\r\n]", text) if part.strip()]


def test_bar_shows_its_count_fraction_and_postfix(capsys):
    b = progress.bar("DEM step", total=10, lines=False)
    b.update(4)
    b.set_postfix_str("max overlap 0.3")
    b.close()
    text = capsys.readouterr().err
    last = _lines(text)[-1]
    assert last.startswith("DEM step:  40%|") and " 4/10 [" in last and "step/s, max overlap 0.3]" in last
    assert text.endswith("\n")  # left on screen (leave=True)


def test_bar_without_total_counts_and_a_disabled_bar_writes_nothing(capsys):
    c = progress.bar("FIRE step", lines=False)
    c.update(3)
    c.close()
    assert _lines(capsys.readouterr().err)[-1].startswith("FIRE step: 3step [")
    d = progress.bar("hidden", total=5, disable=True, lines=False)
    d.update(5)
    d.set_postfix_str("x")
    d.close()
    assert capsys.readouterr().err == ""


def test_say_prints_above_an_open_bar_and_a_bar_not_left_is_erased(capsys):
    b = progress.bar("half", total=4, leave=False, lines=False)
    b.update(2)
    progress.say("packed")
    b.close()
    text = capsys.readouterr().err
    assert "\rpacked\n" in text  # the bar's line cleared first: the message has its own line
    assert re.search(r"\r *\r$", text)  # the bar erased on close
    progress.say("done")
    assert capsys.readouterr().err == "done\n"


def test_where_stderr_is_no_terminal_progress_is_written_as_lines(capsys, monkeypatch):
    """A log file reads line by line: a line per tenth of the work and one at the close, no carriage return."""
    b = progress.bar("DEM steps", total=100)  # pytest's captured stderr is no terminal
    assert isinstance(b, progress.Lines)
    for _ in range(100):
        b.update(1)
        b.set_postfix_str("strain 0.1 %", refresh=False)
    b.close()
    text = capsys.readouterr().err
    assert "\r" not in text
    lines = text.splitlines()
    assert len(lines) == 11  # the first step, 10 % ... 90 %, then the close at 100 %
    assert lines[-1].startswith("DEM steps: 100% 100/100 step, ") and lines[-1].endswith(", strain 0.1 %")
    assert lines[4].startswith("DEM steps:  40% 40/100 step")
    # without a total: a line every LINE_INTERVAL seconds
    monkeypatch.setattr(progress, "LINE_INTERVAL", 0.0)
    c = progress.bar("FIRE step", unit="FIRE step", leave=False)
    c.update(3)
    c.close()
    written = capsys.readouterr().err.splitlines()
    assert len(written) == 1 and written[0].startswith("FIRE step: 3 FIRE step, ")  # (not left: no line at close)
    d = progress.bar("hidden", total=5, disable=True)
    d.update(5)
    d.close()
    assert capsys.readouterr().err == ""


def test_a_process_that_imported_ipykernel_is_no_kernel(monkeypatch):
    """A notebook runner imports ipykernel without being a kernel: its progress is still written as lines."""
    import sys
    import types

    monkeypatch.setitem(sys.modules, "ipykernel", types.ModuleType("ipykernel"))
    assert isinstance(progress.bar("DEM steps", total=10), progress.Lines)
    shell = type("ZMQInteractiveShell", (), {})()
    monkeypatch.setitem(sys.modules, "IPython", types.SimpleNamespace(get_ipython=lambda: shell))
    assert not isinstance(progress.bar("DEM steps", total=10, disable=True), progress.Lines)
