"""``python -m jaxbpm``: the same as the ``jaxbpm`` command (see :mod:`jaxbpm.cli`)."""

import sys

from jaxbpm.cli import main

if __name__ == "__main__":
    sys.exit(main())
