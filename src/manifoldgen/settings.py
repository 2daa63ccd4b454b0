"""``--set KEY=VALUE`` and ``--config FILE`` settings for models and planners.

Values are read as JSON (``0.5``, ``true``, ``[64, 64]``), else taken as a string, and must fit
the type of the known default; unknown keys are refused with the list of known ones. A config
file is a TOML table of the same keys; ``--set`` wins over the file.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from manifoldgen.errors import ManifoldgenError, did_you_mean, not_a_file
from manifoldgen.io import read_toml_file


def parse_settings(pairs: list[str] | None, config: Path | None, known: dict, what: str) -> dict:
    """``["lr=1e-3", ...]`` and a TOML file -> ``{key: value}``, checked against ``known`` (key -> default)."""
    values: dict = {}
    if config is not None:
        if not Path(config).is_file():
            raise ManifoldgenError(f"{not_a_file(config, 'config file')}; give a TOML file of KEY = VALUE lines")
        values.update(read_toml_file(Path(config), "settings file")[0])
    given: set[str] = set()
    for pair in pairs or []:
        key, eq, text = pair.partition("=")
        key = key.strip()
        if not eq or not key:
            raise ManifoldgenError(f"--set '{pair}' is not KEY=VALUE; write e.g. --set {next(iter(known), 'key')}=1")
        if key in given:
            raise ManifoldgenError(f"--set {key} is given twice (which one counts is ambiguous); give each setting "
                                   "once")
        given.add(key)
        try:
            values[key] = json.loads(text)
        except ValueError:
            values[key] = _number(text)
        except RecursionError:
            raise ManifoldgenError(f"--set '{key}' is nested too deeply; give a plain value") from None
    return check_settings(values, known, what)


def _number(text: str) -> float | str:
    """``text`` as a float where Python reads it as one that JSON does not ("nan", "inf"), else the text itself."""
    try:
        return float(text)
    except ValueError:
        return text


def check_settings(values: dict, known: dict, what: str) -> dict:
    """``values`` checked against ``known`` (key -> default) and converted to the defaults' types."""
    out = {}
    for key, value in values.items():
        if key not in known:
            hint = did_you_mean(key, known)  # a near name says enough; else every known one
            raise ManifoldgenError(f"unknown {what} setting '{key}'{hint or '; known: ' + ', '.join(sorted(known))}")
        out[key] = _fit(key, value, known[key], what)
    return out


KINDS = {bool: "true or false", int: "a whole number", float: "a number", str: "a string"}  # a setting's type, said


def _fit(key: str, value, default, what: str):
    """``value`` converted to the type of ``default`` (int -> float allowed), or a clear error."""
    if default is None:
        return value
    if isinstance(value, bool) or isinstance(default, bool):
        if isinstance(value, bool) and isinstance(default, bool):
            return value
    elif isinstance(default, float) and isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise ManifoldgenError(f"{what} setting {key} must be a finite number, got {value!r}")
        return float(value)
    elif isinstance(value, type(default)):
        return value
    kind = KINDS.get(type(default), f"a {type(default).__name__}")
    raise ManifoldgenError(f"{what} setting {key} must be {kind} (like its default {default!r}), got {value!r}")
