"""Scenario-file validation helpers shared by gmis.simulate.scenario and
gmis.simulate.raw_gnss: :class:`ScenarioTable` (gmis.toml_table.TomlTable read key by key
with a type word and a default, leftovers rejected by ``done()``) and the range checks."""

from __future__ import annotations

import copy

from gmis.toml_table import TomlTable

REQUIRED = object()


class ScenarioTable(TomlTable):
    """A scenario table: ``get(key, kind, default)`` with kind "float" | "int" | "str" |
    "vec3" (a number stands for all three axes; returns a list) | "list" (array of
    tables); without a default the key is required. ``done()`` rejects unread keys."""

    def __init__(self, table, where, source):
        super().__init__(table, where, source)

    def get(self, key, kind, default=REQUIRED):
        required = default is REQUIRED
        if key not in self.table:
            self.value(key, required)
            return copy.deepcopy(default)
        if kind == "float":
            return self.number(key)
        if kind == "int":
            return self.integer(key)
        if kind == "str":
            return self.string(key)
        if kind == "vec3":
            value = self.table[key]
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                self.read.add(key)
                return [self._as_float(key, value)] * 3
            return list(self.vector(key))
        if kind == "list":
            value = self.value(key)
            if not isinstance(value, list):
                self.fail_key(key, f"must be an array of tables, got {value!r}")
            return value
        raise AssertionError(kind)

    def checked(self, key, kind, check, *args, default=REQUIRED, **kwargs):
        """``check(self, key, get(key, kind, default), *args, **kwargs)``: the value read
        through one of the range checks below (the key named once)."""
        return check(self, key, self.get(key, kind, default), *args, **kwargs)


def positive(sec, key, value, allow_zero=False):
    """value, checked > 0 (or >= 0)."""
    if value < 0.0 or (value == 0.0 and not allow_zero):
        sec.fail_key(key, f"must be {'>= 0' if allow_zero else '> 0'}, got {value}")
    return value


def nonneg_vec(sec, key, vec):
    if any(x < 0.0 for x in vec):
        sec.fail_key(key, f"must be >= 0, got {vec}")
    return vec


def check_rate(sec, key, rate, lo, hi, imu_rate):
    """A sensor rate (Hz) within lo..hi that divides the IMU rate (epochs on IMU samples)."""
    if not lo <= rate <= hi:
        sec.fail_key(key, f"must be within {lo}..{hi} Hz, got {rate}")
    ratio = imu_rate / rate
    if abs(ratio - round(ratio)) > 1e-9:
        sec.fail_key(key, f"must divide imu_rate_hz ({imu_rate}) so epochs fall on IMU "
                     f"samples, got {rate}")
    return rate


__all__ = ["REQUIRED", "ScenarioTable", "check_rate", "nonneg_vec", "positive"]
