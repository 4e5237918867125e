"""Values in error messages (jaxbpm._text.shown): plain numbers, shortened."""

import numpy as np

from jaxbpm import sample
from jaxbpm._text import shown


def test_shown_plain_and_short():
    assert shown(np.float64(1.5)) == "1.5" and shown(np.array([1.0, 2.0])) == "[1.0, 2.0]"
    assert shown("a") == "'a'" and shown(None) == "None"
    long = shown(list(range(100)))
    assert len(long) == 80 and long.endswith("...") and long.startswith("[0, 1, 2")
    assert shown(list(range(100)), limit=20) == repr(list(range(100)))[:17] + "..."

    class Broken:
        def __repr__(self):
            raise RuntimeError

    assert shown(Broken()) == "a Broken"
    assert not hasattr(sample, "_shown")  # one name, in jaxbpm._text
