"""The version of jaxbpm (one place: the package, its files and the CLI read it here)."""

__version__ = "0.1.0"
