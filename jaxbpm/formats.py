"""Moved to :mod:`jaxbpm.interop.formats`; this name imports it, with a deprecation warning, until the next
release."""

import sys
import warnings

from jaxbpm.interop import formats as _moved

warnings.warn("jaxbpm.formats moved to jaxbpm.interop.formats; the old name goes in the next release",
              DeprecationWarning, stacklevel=2)
sys.modules[__name__] = _moved
