"""The one exception type the library raises for bad input."""


class ManifoldgenError(ValueError):
    """Bad input: the message names the problem and how to fix it."""
