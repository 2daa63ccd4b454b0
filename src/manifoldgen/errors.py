"""The one exception type the library raises for bad input, and its message for unknown names."""

import difflib


class ManifoldgenError(ValueError):
    """Bad input: the message names the problem and how to fix it."""


def unknown_name(kind: str, name: str, known: list[str]) -> ManifoldgenError:
    """``unknown <kind> '<name>'; did you mean ...? known <kind>s: ...`` for a registry lookup."""
    close = difflib.get_close_matches(name, known, n=2)
    hint = f"did you mean {', '.join(close)}? " if close else ""
    return ManifoldgenError(f"unknown {kind} '{name}'; {hint}known {kind}s: {', '.join(known)}")
