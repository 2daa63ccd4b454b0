"""The one exception type the library raises for bad input, its message for unknown names, the guard
every file reader wears (:func:`file_reader`), :class:`SamplerFailed`, which ends a search unsolved, and the
import of an optional extra's module (:func:`require`)."""

import difflib
import functools
import importlib
import os


class ManifoldgenError(ValueError):
    """Bad input: the message names the problem and how to fix it."""


class SamplerFailed(Exception):
    """The sampler could not produce a configuration: the query ends unsolved."""


def unknown_name(kind: str, name: str, known: list[str]) -> ManifoldgenError:
    """``unknown <kind> '<name>'; did you mean ...? known <kind>s: ...`` for a registry lookup."""
    close = difflib.get_close_matches(name, known, n=2)
    hint = f"did you mean {', '.join(close)}? " if close else ""
    return ManifoldgenError(f"unknown {kind} '{name}'; {hint}known {kind}s: {', '.join(known)}")


def check_keys(data: dict, known, what: str) -> None:
    """Refuse a key of ``data`` that is not in ``known`` (a misspelt key would silently drop what it names)."""
    for key in data:
        if key not in known:
            close = difflib.get_close_matches(str(key), list(known), n=1)
            hint = f"did you mean '{close[0]}'? " if close else ""
            raise ManifoldgenError(f"{what}: unknown key '{key}'; {hint}known keys: {', '.join(known)}")


DAMAGED = (KeyError, TypeError, ValueError, AttributeError, IndexError, RuntimeError, OverflowError, RecursionError)


def not_a_file(path, what: str = "file") -> str:
    """Why ``path`` cannot be read as a ``what`` (a regular file): not found, a directory, or a device, pipe or
    socket; the start of a one-line error."""
    path = os.fspath(path)
    if os.path.isdir(path):
        return f"{what} {path} is a directory, not a file"
    if os.path.exists(path):
        return f"{what} {path} is not a regular file (a device, pipe or socket)"
    return f"{what} not found: {path}"


def user_code(exc: BaseException) -> str | None:
    """``FILE, line N`` of the innermost frame of ``exc`` in a user's module (not this package, not an installed
    package nor the standard library; a syntax error's own file and line), or None."""
    import sys
    import sysconfig
    import traceback

    ours = [os.path.dirname(os.path.realpath(__file__)), *{sysconfig.get_paths()[k] for k in ("stdlib", "purelib",
                                                                                        "platlib")}, sys.prefix]
    frames = [(f.filename, f.lineno) for f in traceback.extract_tb(exc.__traceback__)]
    if isinstance(exc, SyntaxError) and exc.filename:
        frames.append((exc.filename, exc.lineno))
    for filename, line in reversed(frames):
        if not filename.startswith("<") and not any(os.path.realpath(filename).startswith(o) for o in ours):
            return f"{filename}, line {line}"
    return None


def file_reader(read):
    """Decorate a reader of files: an exception that a damaged or foreign file's content raises deep inside
    (a string where a number belongs, a missing key ...) becomes one ManifoldgenError naming the file."""
    @functools.wraps(read)
    def wrapper(*args, **kwargs):
        try:
            return read(*args, **kwargs)
        except ManifoldgenError:
            raise
        except DAMAGED as exc:
            if user_code(exc) is not None:  # the user's own module failed, not the file: the caller names it
                raise
            source = next((str(a) for a in args if isinstance(a, (str, os.PathLike))), "the file")
            why = (str(exc).strip().splitlines() or [""])[0][:120]
            raise ManifoldgenError(f"{source}: damaged or unexpected content ({type(exc).__name__}: {why}); "
                                   "regenerate the file or fix it") from None
    return wrapper


def require(module: str, extra: str, what: str):
    """Import ``module``, which ``what`` needs and the package's ``extra`` extra installs; when it is not
    installed, a one-line error naming the extra and its install command. (A module that is installed but
    fails to import raises its own error.)"""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name is None or not (module == exc.name or module.startswith(exc.name + ".")):
            raise
        raise ManifoldgenError(f"{what} needs the [{extra}] extra: pip install 'manifoldgen[{extra}]'") from None
