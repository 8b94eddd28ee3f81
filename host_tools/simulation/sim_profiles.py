"""Chamber temperature programs of host_tools.simulation.sim: :class:`Profile` (a piecewise-linear table
t_s -> temp_c, from a CSV file or a table) and the paper's programs (cycles, slow ramp, constant).
Units: ``_s`` seconds, ``_c`` degC, ``_cpm`` degC/min.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

# ---------------------------------------------------------------------------------------------
# chamber profiles
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Profile:
    """A chamber temperature program: breakpoints ``t_s`` [s, strictly increasing, first >= 0] and
    ``temp_c`` [degC], linear in between; before the first breakpoint the first temperature, after
    the last one the last temperature holds."""

    t_s: tuple
    temp_c: tuple
    name: str = "table"

    def __post_init__(self):
        t = np.asarray(self.t_s, float)
        y = np.asarray(self.temp_c, float)
        where = f"chamber profile '{self.name}'"
        if t.ndim != 1 or y.ndim != 1 or len(t) != len(y):
            raise ValueError(f"{where}: t_s and temp_c must be 1-D of equal length ({t.shape} vs {y.shape})")
        if len(t) < 1:
            raise ValueError(f"{where}: needs at least one breakpoint")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
            raise ValueError(f"{where}: NaN/inf in the table")
        if t[0] < 0:
            raise ValueError(f"{where}: first time {t[0]} s is negative")
        if np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise ValueError(f"{where}: t_s not strictly increasing at row {k} ({t[k - 1]} then {t[k]})")
        if np.any(y < -273.15):
            raise ValueError(f"{where}: temperature below absolute zero")
        object.__setattr__(self, "t_s", tuple(float(v) for v in t))
        object.__setattr__(self, "temp_c", tuple(float(v) for v in y))

    @property
    def end_s(self) -> float:
        return self.t_s[-1]

    def __call__(self, t) -> np.ndarray:
        """Chamber temperature [degC] at times ``t`` [s]."""
        return np.interp(np.asarray(t, float), self.t_s, self.temp_c)

    @classmethod
    def from_table(cls, table, name: str = "table") -> "Profile":
        """From rows ``(t_s, temp_c)`` (a list of pairs or an (n, 2) array)."""
        arr = np.asarray(table, float)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ValueError(f"chamber profile '{name}': need rows (t_s, temp_c), got shape {arr.shape}")
        return cls(tuple(arr[:, 0]), tuple(arr[:, 1]), name)

    @classmethod
    def from_csv(cls, path) -> "Profile":
        """From a 2-column CSV ``t_s,temp_c`` (an optional header row; ``#`` lines are comments)."""
        path = os.fspath(path)
        rows = []
        with open(path, encoding="utf-8") as fh:
            for lineno, line in enumerate(fh, 1):
                text = line.strip()
                if not text or text.startswith("#"):
                    continue
                cells = [c.strip() for c in text.split(",")]
                try:
                    vals = [float(c) for c in cells]
                except ValueError:
                    if not rows and lineno == _first_content_line(path):
                        continue  # header
                    raise ValueError(f"{path}:{lineno}: not two numbers t_s,temp_c: {text!r}") from None
                if len(vals) != 2:
                    raise ValueError(f"{path}:{lineno}: {len(vals)} cells, a profile row is t_s,temp_c")
                rows.append(vals)
        if not rows:
            raise ValueError(f"{path}: no profile rows (expected lines t_s,temp_c)")
        try:
            return cls.from_table(rows, name=os.path.basename(path))
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None


def _first_content_line(path) -> int:
    with open(path, encoding="utf-8") as fh:
        for lineno, line in enumerate(fh, 1):
            if line.strip() and not line.strip().startswith("#"):
                return lineno
    return 0


def cycle_profile(rate_c_per_min: float, low_c: float = -20.0, high_c: float = 20.0,
                  hold_s: float = 7200.0, n_cycles: int = 2, end_hold_s: float | None = None) -> Profile:
    """Temperature cycles (paper 4.3): from ``high_c`` (held ``end_hold_s``, default ``hold_s / 2``)
    ramp to ``low_c`` at ``rate_c_per_min``, hold ``hold_s``, ramp back, hold, ... ``n_cycles``
    times; the last hold at ``high_c`` lasts ``end_hold_s`` (so both extremes get equal time)."""
    if end_hold_s is None:
        end_hold_s = hold_s / 2.0
    if not rate_c_per_min > 0 or not hold_s >= 0 or not end_hold_s >= 0 or n_cycles < 1 or not high_c > low_c:
        raise ValueError(f"cycle profile: need rate > 0, holds >= 0, n_cycles >= 1, high > low "
                         f"(got {rate_c_per_min}, {hold_s}, {end_hold_s}, {n_cycles}, {low_c}..{high_c})")
    ramp = (high_c - low_c) / rate_c_per_min * 60.0
    t, y = [0.0], [high_c]
    for k in range(n_cycles):
        for target in (low_c, high_c):
            hold = end_hold_s if (k == 0 and target == low_c) else hold_s
            t += [t[-1] + hold, t[-1] + hold + ramp]
            y += [y[-1], target]
    t.append(t[-1] + end_hold_s)
    y.append(y[-1])
    return Profile(tuple(t), tuple(y), f"cycle {low_c:g}..{high_c:g} degC at {rate_c_per_min:g} degC/min, "
                                       f"holds {hold_s:g} s, {n_cycles} cycles")


def slow_ramp_profile(rate_c_per_min: float = 0.5, hold_s: float = 3600.0) -> Profile:
    """Paper 4.2 / Table 1: hold at -40 degC, ramp slowly to 60 degC, hold, ramp down to 25 degC,
    hold."""
    r = 60.0 / rate_c_per_min
    t = [0.0, hold_s, hold_s + 100 * r, 2 * hold_s + 100 * r, 2 * hold_s + 135 * r, 3 * hold_s + 135 * r]
    return Profile(tuple(t), (-40.0, -40.0, 60.0, 60.0, 25.0, 25.0),
                   f"slow ramp -40 -> 60 -> 25 degC at {rate_c_per_min:g} degC/min, holds {hold_s:g} s")


def constant_profile(temp_c: float = 20.0, duration_s: float = 3600.0) -> Profile:
    """Constant chamber temperature (static runs, power-on at ambient)."""
    return Profile((0.0, float(duration_s)), (float(temp_c), float(temp_c)), f"constant {temp_c:g} degC")
