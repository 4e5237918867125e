"""Moved to :mod:`jaxbpm.interop.conventions`; this name imports it, with a deprecation warning, until the next
release."""

import sys
import warnings

from jaxbpm.interop import conventions as _moved

warnings.warn("jaxbpm.conventions moved to jaxbpm.interop.conventions; the old name goes in the next release",
              DeprecationWarning, stacklevel=2)
sys.modules[__name__] = _moved
