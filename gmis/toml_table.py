"""One TOML table read through typed accessors — the one validator of recipes
(gmis.recipe) and scenarios (gmis.simulate.scenario).

Every problem raises :class:`gmis.errors.GmisInputError` naming the file and the dotted
key (``imu.rate_hz``), so the CLI prints one line and exits 2. Unknown keys are rejected
either at once (``keys`` given: with a "did you mean" suggestion) or by :meth:`done`
after the known keys were read (``keys`` None).
"""

from __future__ import annotations

import difflib
import math
from typing import Any

from gmis.errors import GmisInputError


def suggest(key: str, valid) -> str:
    """' (did you mean 'x'?)' for the closest valid name, or ''."""
    close = difflib.get_close_matches(key, list(valid), n=1, cutoff=0.5)
    return f" (did you mean {close[0]!r}?)" if close else ""


def type_name(value) -> str:
    return {str: "a string", bool: "a boolean", int: "an integer", float: "a number",
            list: "a list", dict: "a table"}.get(type(value), type(value).__name__)


class TomlTable:
    """Reads one TOML table; every error names the file and the dotted key."""

    def __init__(self, table: Any, name: str, source: str, keys=None):
        self.name, self.source, self.keys = name, source, keys
        if not isinstance(table, dict):
            self.fail(name, f"must be a table, got {type_name(table)}")
        self.table = table
        self.read: set[str] = set()
        for key in table if keys is not None else ():
            if key not in keys:
                self.fail(
                    f"{name}.{key}",
                    f"unknown key in [{name}]{suggest(key, keys)}; valid keys: "
                    + ", ".join(keys),
                )

    def fail(self, dotted: str, message: str):
        raise GmisInputError(f"{dotted}: {message}", source=self.source)

    def fail_key(self, key: str, message: str):
        self.fail(f"{self.name}.{key}", message)

    def has(self, key: str) -> bool:
        return key in self.table

    def value(self, key, required=False):
        """The raw value of ``key`` (None when absent and not required)."""
        self.read.add(key)
        if key not in self.table:
            if required:
                self.fail_key(key, f"required key missing from [{self.name}]")
            return None
        return self.table[key]

    def done(self):
        """Reject the keys that were not read (tables opened without ``keys``)."""
        left = [k for k in self.table if k not in self.read]
        if left:
            self.fail(self.name, "unknown key(s) " + ", ".join(sorted(left)))

    def boolean(self, key, default=None) -> bool | None:
        value = self.value(key)
        if value is None:
            return default
        if not isinstance(value, bool):
            self.fail_key(key, f"expected true or false, got {type_name(value)}")
        return value

    def string(self, key, choices=None, required=False, default=None) -> str | None:
        value = self.value(key, required)
        if value is None:
            return default
        if not isinstance(value, str):
            self.fail_key(key, f"expected a string, got {type_name(value)}")
        if choices is not None and value not in choices:
            self.fail_key(key, f"invalid value {value!r}{suggest(value, choices)}; allowed: "
                          + ", ".join(repr(c) for c in choices))
        return value

    def number(self, key, required=False, default=None, minimum=None, positive=False,
               maximum=None) -> float | None:
        value = self.value(key, required)
        if value is None:
            return default
        x = self._as_float(key, value)
        self._check_range(key, x, minimum, positive, maximum)
        return x

    def integer(self, key, required=False, default=None, choices=None, minimum=None):
        value = self.value(key, required)
        if value is None:
            return default
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail_key(key, f"expected an integer, got {type_name(value)}")
        if choices is not None and value not in choices:
            self.fail_key(key, f"must be one of {list(choices)}, got {value}")
        if minimum is not None and value < minimum:
            self.fail_key(key, f"must be >= {minimum}, got {value}")
        return value

    def vector(self, key, length=3, required=False, default=None, minimum=None,
               positive=False, scale=1.0) -> tuple | None:
        value = self.value(key, required)
        if value is None:
            return default
        if not isinstance(value, list):
            self.fail_key(key, f"expected a list of {length} numbers, got {type_name(value)}")
        if len(value) != length:
            self.fail_key(key, f"expected a list of {length} numbers, got {len(value)}")
        out = []
        for item in value:
            x = self._as_float(key, item)
            self._check_range(key, x, minimum, positive, None)
            out.append(x * scale)
        return tuple(out)

    def _as_float(self, key, value) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail_key(key, f"expected a number, got {type_name(value)} {value!r}")
        x = float(value)
        if not math.isfinite(x):
            self.fail_key(key, f"must be finite, got {value}")
        return x

    def _check_range(self, key, x, minimum, positive, maximum):
        if positive and not x > 0.0:
            self.fail_key(key, f"must be > 0, got {x:g}")
        if minimum is not None and x < minimum:
            self.fail_key(key, f"must be >= {minimum:g}, got {x:g}")
        if maximum is not None and x > maximum:
            self.fail_key(key, f"must be <= {maximum:g}, got {x:g}")


__all__ = ["TomlTable", "suggest", "type_name"]
