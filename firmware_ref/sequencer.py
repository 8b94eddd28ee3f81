"""The mode-reversal sequencer in fixed point (Python-integer reference): a timer state machine
that drives the virtual switches (paper Fig. 3c) and the combiner that turns the raw rate words
into the bias-cancelled output, exactly per host_tools.golden.reversal (its module doc is the spec).

Timer (self-timed operation)
----------------------------
States (formats.STATE_NAMES): power-on (``power_on_n`` samples), exchange to mode 1
(``exchange_n``), mode 1 (``dwell_n``), exchange to mode 2 (``exchange_n``), mode 2 (``dwell_n``),
then exchange to mode 1 again, ...; an FTR table (combiner 0) goes from power-on to the FTR state
forever.  Per sample::

    while state != FTR and cnt >= length(state):   # at most 3 passes (zero-length states skipped)
        state = next(state); cnt = 0
    emit state; if state != FTR: cnt += 1

so with ``power_on_n = 0`` the modes are those of host_tools.simulation.sim_physics.mode_sequence (exchange first).
Each state has a run-log mode (3, 3, 1, 3, 2, 0), a rate sign and the virtual-switch bits
(formats.STATE_VS).  A restart resets the timer as at power-on.  Driven by a logged mode column
instead, the state is derived from the mode (an exchange is "to 2" after a mode-1 window, else
"to 1").

Combiner (integer form of host_tools.golden.reversal)
----------------------------------------------
State: ``cur`` (open window's mode, 0 none), ``acc`` (int64 sum of c = s R), ``cnt`` (used
samples), ``pos`` (settle counter, saturating at settle_n); per mode o in {1, 2}: ``ncommit[o]``
(0, 1, 2+), ``W[o]`` (mean, LSB 2^-20 deg/h), ``span[o]`` (last - first used index of its last
window), ``age[o]`` (samples since that window's last used sample, saturating at 2^31 - 1) and
``slope[o]`` (LSB 2^-36 deg/h per half-sample).  No absolute sample index is kept, so nothing
wraps on long runs.  Per sample with mode m, rate word R, restart r::

    if r: cur = 0; acc = cnt = pos = 0; ncommit[1] = ncommit[2] = 0; slope[1] = slope[2] = 0
    age[1] = sat(age[1] + 1); age[2] = sat(age[2] + 1)
    if m != cur:
        if cur != 0 and cnt >= 1:                                  # commit the window
            mean = div_round_scaled(acc, cnt, 10)                  # RHU(acc 2^10 / cnt)
            sp = cnt - 1
            if ncommit[cur] >= 1:                                  # trend slope
                dc2 = 2 (age[cur] - 1) - sp + span[cur]            # centre change, half-samples
                slope[cur] = clamp(div_round_scaled(mean - W[cur], dc2, 16), +-(2^40 - 1))  [FLAG_SAT]
            W[cur] = mean; span[cur] = sp; age[cur] = 1; ncommit[cur] = min(ncommit[cur] + 1, 2)
        cur = m if m in (1, 2) else 0; acc = cnt = pos = 0
    if cur != 0:
        c = R if cur == 1 else -R
        if pos >= settle_n:
            if cnt < 2^31 - 1: acc += c; cnt += 1   else: FLAG_SAT
            o = 3 - cur
            if ncommit[o] >= 1 and age[o] <= max_stale_n:
                other = W[o]
                if trend:
                    d = clamp(2 age[o] + span[o], 0, 2^22 - 1)     [FLAG_SAT]
                    other += RHU(slope[o] * d, 16)
                y = (c << 10) + other; valid                        # y: LSB 2^-21 deg/h
        else: pos += 1

Regress, then reverse (order 1, docs/REGRESS_THEN_REVERSE.md; golden host_tools.golden.reversal)
-----------------------------------------------------------------------------
The combiner takes the **residual word** instead of c: at a sample past settling (``pos >=
settle_n``) whose rate estimator is warm (``warm`` false)::

    x = symsat32(RHU(c 2^11 - B, 11))          # r = c - B: int32, LSB 2^-10 deg/h  [FLAG_SAT]

with B the bias of the sample's bank (LSB 2^-21 deg/h), and x replaces c everywhere above (window
sums, means, slopes, y).  A warm-up sample past settling is not used: it neither enters the
window nor gives a valid output (the golden's "used" rule; order 0 keeps the legacy rule, where
warm-up samples enter the window and only the output is invalid).  Combiner 3 (none): ``y = x <<
11``, valid at every used sample.  The pipeline then outputs OUT = RHU(y, 11) (B is already in y)
instead of RHU(y - B, 11).

Input-invalid samples (FORMATS.md "The input-invalid bit"; golden host_tools.golden.reversal)
-----------------------------------------------------------------------------------------
One more bit of state, ``taint`` (the open window held an input-invalid sample; cleared at a
restart and whenever a window opens).  An input-invalid sample of a mode-1/2 window sets it (at
any position, settling included) and is never used (no sum, not valid); at the mode change a
tainted window is not committed (as if its count were 0), so W, span, age, slope and ncommit of
that mode keep the last clean window's values and no pairing uses the tainted one::

    if cur != 0 and invalid: taint = 1
    commit only if cnt >= 1 and not taint;  on a window switch: taint = 0
    if cur != 0 and pos >= settle_n and invalid: not used, not valid

FTR (combiner 0): ``y = R << 11``, always valid.  The centre of a window is (first + last)/2, so
``2 (i - centre[o]) = 2 age[o] + span[o]`` and the golden ``slope (i - centre)`` equals
``(W - W_prev) / dc2 * d``.  Invalid samples keep the last valid y (0 before the first).
"""
from __future__ import annotations

from dataclasses import dataclass

from firmware_ref import formats as F
from firmware_ref.arith import clamp, div_round_scaled, rshift_round, sat_signed

FTR, PAIR, TREND, NONE = 0, 1, 2, 3


def state_length(table, state: int) -> int:
    """Samples the timer spends in ``state`` (FTR: unbounded, -1)."""
    if state == F.ST_POWER_ON:
        return table.power_on_n
    if state in (F.ST_EXCH_TO_1, F.ST_EXCH_TO_2):
        return table.exchange_n
    if state in (F.ST_MODE_1, F.ST_MODE_2):
        return table.dwell_n
    return -1


def next_state(table, state: int) -> int:
    if state == F.ST_POWER_ON:
        return F.ST_FTR if table.combiner == FTR else F.ST_EXCH_TO_1
    if state == F.ST_MODE_2:
        return F.ST_EXCH_TO_1
    return state + 1


class Timer:
    """Self-timed sequencer state machine (see the module doc)."""

    def __init__(self, table):
        self.table = table
        self.reset()

    def reset(self):
        self.state = F.ST_POWER_ON
        self.cnt = 0

    def step(self) -> int:
        """Advance one sample; returns the state of this sample."""
        for _ in range(3):
            if self.state == F.ST_FTR or self.cnt < state_length(self.table, self.state):
                break
            self.state = next_state(self.table, self.state)
            self.cnt = 0
        else:  # pragma: no cover - dwell_n >= 1 makes a third skip impossible
            raise AssertionError("timer: no state of non-zero length")
        if self.state != F.ST_FTR:
            self.cnt += 1
        return self.state


@dataclass
class SeqOut:
    """One sample of the sequencer: state, run-log mode, virtual-switch bits, rate sign, combined
    valid, window sum and count (after this sample), combined output y (LSB 2^-21 deg/h, held
    when not valid), saturation event."""

    state: int
    mode: int
    vs: int
    sign: int
    valid: bool
    acc: int
    cnt: int
    y: int
    sat: bool


class Combiner:
    """Integer mode-reversal combiner (see the module doc)."""

    def __init__(self, table):
        self.table = table
        self.y_hold = 0
        self.last_window = 0
        self.reset()

    def reset(self):
        self.cur = 0
        self.acc = 0
        self.cnt = 0
        self.pos = 0
        self.ncommit = [0, 0, 0]
        self.W = [0, 0, 0]
        self.span = [0, 0, 0]
        self.age = [0, 0, 0]
        self.slope = [0, 0, 0]
        self.taint = False

    def step(self, mode: int, r: int, restart: bool, b: int = 0, warm: bool = False,
             invalid: bool = False) -> tuple[bool, int, bool]:
        """One sample: ``(valid, y, sat)`` (y held when not valid).  ``b`` (the sample's bias B,
        LSB 2^-21 deg/h) and ``warm`` (rate estimator in warm-up) are read by order 1 only;
        ``invalid``: the sample's input-invalid bit (see the module doc)."""
        t = self.table
        sat = False
        if t.combiner == FTR:
            self.y_hold = r << (F.Y_FRAC - F.RATE_FRAC)
            return True, self.y_hold, False
        if restart:
            self.cur = 0
            self.acc = self.cnt = self.pos = 0
            self.ncommit[1] = self.ncommit[2] = 0
            self.slope[1] = self.slope[2] = 0
            self.taint = False
        for o in (1, 2):
            self.age[o] = min(self.age[o] + 1, F.COUNT_MAX)
        cur = self.cur
        if mode != cur:
            if cur != 0 and self.cnt >= 1 and not self.taint:
                mean = div_round_scaled(self.acc, self.cnt, F.MEAN_EXTRA)
                sp = self.cnt - 1
                if self.ncommit[cur] >= 1:
                    dc2 = 2 * (self.age[cur] - 1) - sp + self.span[cur]
                    s = div_round_scaled(mean - self.W[cur], dc2, F.SLOPE_EXTRA)
                    self.slope[cur], c = clamp(s, -F.SLOPE_MAX, F.SLOPE_MAX)
                    sat |= c
                self.W[cur] = mean
                self.span[cur] = sp
                self.age[cur] = 1
                self.ncommit[cur] = min(self.ncommit[cur] + 1, 2)
            self.cur = cur = mode if mode in (1, 2) else 0
            if cur:
                self.last_window = cur
            self.acc = self.cnt = self.pos = 0
            self.taint = False
        valid = False
        if cur != 0:
            c = r if cur == 1 else -r
            if invalid:
                self.taint = True
            if self.pos >= t.settle_n:
                if invalid:
                    return False, self.y_hold, sat
                if t.order == 1:
                    if warm:
                        return False, self.y_hold, sat
                    c, cs = sat_signed(rshift_round((c << F.OUT_SHIFT) - b, F.OUT_SHIFT), 32)
                    sat |= cs
                    if t.combiner == NONE:
                        if self.cnt < F.COUNT_MAX:
                            self.acc += c
                            self.cnt += 1
                        else:
                            sat = True
                        self.y_hold = c << F.OUT_SHIFT
                        return True, self.y_hold, sat
                if self.cnt < F.COUNT_MAX:
                    self.acc += c
                    self.cnt += 1
                else:
                    sat = True
                o = 3 - cur
                if self.ncommit[o] >= 1 and self.age[o] <= t.max_stale_n:
                    other = self.W[o]
                    if t.combiner == TREND:
                        d, cd = clamp(2 * self.age[o] + self.span[o], 0, F.D_MAX)
                        sat |= cd
                        other += rshift_round(self.slope[o] * d, F.SLOPE_EXTRA)
                    self.y_hold = (c << F.MEAN_EXTRA) + other
                    valid = True
            else:
                self.pos += 1
        return valid, self.y_hold, sat


def state_of_mode(mode: int, last_window: int) -> int:
    """Sequencer state of a logged mode (log-driven operation)."""
    if mode == 0:
        return F.ST_FTR
    if mode == 1:
        return F.ST_MODE_1
    if mode == 2:
        return F.ST_MODE_2
    return F.ST_EXCH_TO_2 if last_window == 1 else F.ST_EXCH_TO_1


class Sequencer:
    """Timer + combiner.  ``self_timed``: the timer makes the modes (``step(None, r, restart)``);
    else ``step(mode, r, restart)`` takes the logged mode."""

    def __init__(self, table, self_timed: bool = False):
        self.table = table
        self.self_timed = self_timed
        self.timer = Timer(table)
        self.comb = Combiner(table)

    def mode_step(self, mode, restart: bool) -> tuple[int, int]:
        """First half of a sample: ``(state, mode)`` (timer, or the logged mode)."""
        if self.self_timed:
            if restart:
                self.timer.reset()
            state = self.timer.step()
            return state, F.STATE_MODE[state]
        return state_of_mode(int(mode), self.comb.last_window), int(mode)

    def combine_step(self, state: int, mode: int, r: int, restart: bool, b: int = 0, warm: bool = False,
                     invalid: bool = False) -> SeqOut:
        """Second half: the combiner (``b``, ``warm``, ``invalid``: see Combiner.step)."""
        valid, y, sat = self.comb.step(mode, r, restart, b, warm, invalid)
        return SeqOut(state, mode, F.STATE_VS[state], F.STATE_SIGN[state], valid, self.comb.acc,
                      self.comb.cnt, y, sat)

    def step(self, mode, r: int, restart: bool, b: int = 0, warm: bool = False, invalid: bool = False) -> SeqOut:
        state, mode = self.mode_step(mode, restart)
        return self.combine_step(state, mode, r, restart, b, warm, invalid)
