"""The progress display: the bar's text on stderr (read from pytest's captured stream), a counter without a total, a
disabled bar writing nothing, and messages printed on a line of their own above an open bar."""

import re

from jaxbpm import progress


def _lines(text: str) -> list[str]:
    return [part.strip() for part in re.split(r"[\r\n]", text) if part.strip()]


def test_bar_shows_its_count_fraction_and_postfix(capsys):
    b = progress.bar("DEM step", total=10)
    b.update(4)
    b.set_postfix_str("max overlap 0.3")
    b.close()
    text = capsys.readouterr().err
    last = _lines(text)[-1]
    assert last.startswith("DEM step:  40%|") and " 4/10 [" in last and "step/s, max overlap 0.3]" in last
    assert text.endswith("\n")  # left on screen (leave=True)


def test_bar_without_total_counts_and_a_disabled_bar_writes_nothing(capsys):
    c = progress.bar("FIRE step")
    c.update(3)
    c.close()
    assert _lines(capsys.readouterr().err)[-1].startswith("FIRE step: 3step [")
    d = progress.bar("hidden", total=5, disable=True)
    d.update(5)
    d.set_postfix_str("x")
    d.close()
    assert capsys.readouterr().err == ""


def test_say_prints_above_an_open_bar_and_a_bar_not_left_is_erased(capsys):
    b = progress.bar("half", total=4, leave=False)
    b.update(2)
    progress.say("packed")
    b.close()
    text = capsys.readouterr().err
    assert "\rpacked\n" in text  # the bar's line cleared first: the message has its own line
    assert re.search(r"\r *\r$", text)  # the bar erased on close
    progress.say("done")
    assert capsys.readouterr().err == "done\n"
