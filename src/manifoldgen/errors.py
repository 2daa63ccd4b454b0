"""The one exception type the library raises for bad input, its message for unknown names, the guard
every file reader wears (:func:`file_reader`), :class:`SamplerFailed`, which ends a search unsolved, the
import of an optional extra's module (:func:`require`), and what keeps a refusal one short line however large the
values it names (:func:`short`, :func:`listed`, :func:`differences`)."""

import difflib
import errno
import functools
import importlib
import json
import os

SHOWN = 3  # the items (differences, names) a refusal names before it counts the rest


class ManifoldgenError(ValueError):
    """Bad input: the message names the problem and how to fix it."""


class SamplerFailed(Exception):
    """The sampler could not produce a configuration: the query ends unsolved."""


def unknown_name(kind: str, name: str, known: list[str]) -> ManifoldgenError:
    """``unknown <kind> '<name>'; did you mean ...? known <kind>s: ...`` for a registry lookup."""
    close = difflib.get_close_matches(name, known, n=2)
    hint = f"did you mean {', '.join(close)}? " if close else ""
    return ManifoldgenError(f"unknown {kind} '{name}'; {hint}known {kind}s: {', '.join(known)}")


def did_you_mean(name, known) -> str:
    """`` (did you mean 'NAME'?)`` for the one of ``known`` nearest ``name``, or '' when none is near."""
    close = difflib.get_close_matches(str(name), list(known), n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""


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
    if os.path.islink(path):  # a link that leads nowhere
        try:
            os.stat(path)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                return (f"{what} {path} is a symbolic link loop (its links lead back to themselves); give the file "
                        "itself")
        return f"{what} {path} is a symbolic link to a missing file ({os.readlink(path)})"
    return f"{what} not found: {path}"


def user_code(exc: BaseException) -> str | None:
    """``FILE, line N`` of the innermost frame of ``exc`` in a user's module (a file that exists: not this package,
    not an installed package nor the standard library, nor a compiled extension's source such as numpy's
    ``numpy/random/_generator.pyx``; a syntax error's own file and line), or None."""
    import sys
    import sysconfig
    import traceback

    ours = [os.path.dirname(os.path.realpath(__file__)), *{sysconfig.get_paths()[k] for k in ("stdlib", "purelib",
                                                                                        "platlib")}, sys.prefix]
    frames = [(f.filename, f.lineno) for f in traceback.extract_tb(exc.__traceback__)]
    if isinstance(exc, SyntaxError) and exc.filename:
        frames.append((exc.filename, exc.lineno))
    for filename, line in reversed(frames):
        if (not filename.startswith("<") and os.path.isfile(filename)
                and not any(os.path.realpath(filename).startswith(o) for o in ours)):
            return f"{filename}, line {line}"
    return None


def file_reader(read):
    """Decorate a reader of files: an exception that a damaged or foreign file's content raises deep inside
    (a string where a number belongs, a missing key ...) becomes one ManifoldgenError naming the file, and so does
    a user's module exiting as the file's task is built (naming its file and line)."""
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
        except SystemExit as exc:  # a user's module exiting: through the API it would end the caller's program
            where = user_code(exc)
            if where is None:
                raise
            raise ManifoldgenError(f"user code {where} called exit({exc.code!r}) while its task was read; a "
                                   "constraint's module must not exit: fix it (see docs/tasks.md)") from None
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


def short(value, width: int = 40) -> str:
    """``value`` as at most ``width`` characters of JSON (a file's meta may hold anything)."""
    text = json.dumps(value, default=repr)
    return text if len(text) <= width else text[:width - 3] + "..."


def listed(items: list[str], separator: str = "; ") -> str:
    """The first :data:`SHOWN` of ``items`` joined, the rest counted: ``a; b; c (and 2 more)``."""
    more = len(items) - SHOWN
    return separator.join(items[:SHOWN]) + (f" (and {more} more)" if more > 0 else "")


def differences(old, new, where: str = "", words: tuple[str, str] = ("then", "now")) -> str:
    """Where the JSON values ``old`` and ``new`` differ, leaf by leaf (``'KEY: OLD then, NEW now'``, values cut
    short; ``where``: the values' own key), :func:`listed`; '' when they are equal."""
    return listed(_leaves(json.loads(json.dumps(old)), json.loads(json.dumps(new)), where, words))


def _leaves(old, new, where: str, words: tuple[str, str]) -> list[str]:
    """``'KEY: OLD then, NEW now'`` for every leaf that differs (dicts descended in ``new``'s key order, equally long
    lists of dicts item by item; lists that look the same cut short: their first differing item, or their lengths)."""
    if isinstance(old, dict) and isinstance(new, dict):
        return [line for key in [*new, *(key for key in old if key not in new)]
                for line in _leaves(old.get(key), new.get(key), f"{where}.{key}" if where else str(key), words)]
    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new) and old != new \
            and any(isinstance(v, dict) for v in old):
        return [line for i, (a, b) in enumerate(zip(old, new)) for line in _leaves(a, b, f"{where}[{i}]", words)]
    if isinstance(old, list) and isinstance(new, list) and old != new and short(old, 24) == short(new, 24):
        first = next((i for i, (a, b) in enumerate(zip(old, new)) if a != b), None)
        if first is not None:
            return _leaves(old[first], new[first], f"{where}[{first}]", words)
        return [f"{where or 'settings'}: {len(old)} items {words[0]}, {len(new)} items {words[1]} (the first "
                f"{min(len(old), len(new))} alike)"]
    return [] if old == new else [f"{where or 'settings'}: {short(old, 24)} {words[0]}, {short(new, 24)} {words[1]}"]
