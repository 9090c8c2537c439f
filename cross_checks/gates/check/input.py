"""``rbcheck check``, step 1: what a trajectory file says, as people write it (docs/check.md, "What to
give it").

Turns the rows of a trajectory CSV (read by column name, :func:`cross_checks.core.trajectory.read_columns`)
into a :class:`CheckInput`: the simulator's step ``h``, how many steps each row interval spans, the
true time of every row (``n_k h``: rows are mapped to steps from their INTERVALS, and the recorded
times checked against ``n_k h`` within :func:`single_precision_time_bound`), the precision the values
were written in (per column, the largest rounding quantum shown), which quantities the file holds, and
what had to be decided on the way (notes). Everything the checker cannot work with is a
:class:`CheckError` (exit 2) naming the file, the line or column and the reason.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import BLOCKS
from cross_checks.core.trajectory import QUANTITY_GROUPS
from reference_sim.state import Q

__all__ = ["CheckError", "CheckInput", "prepare_input", "printed_half_quantum", "written_digits",
           "single_precision_time_bound", "interval_bound", "snap_step"]


#: Unit roundoff of double and single precision.
EPS64 = 2.0 ** -53
EPS32 = 2.0 ** -24


class CheckError(ValueError):
    """A trajectory that cannot be checked (message: file, field, reason) -> exit 2."""


@dataclass
class CheckInput:
    """One trajectory file prepared for checking.

    source : the file name used in messages.
    t_rec_s : (K,) recorded times, s.  t_s : (K,) true times ``n_k · h`` (s).
    n_steps : (K,) step index of each row (0 for the first).  span_steps : (K−1,) steps per row interval.
    h_s : the simulator's step, s (None in variable-step mode).
    span_s : (K−1,) length of each row interval, s.
    y : (K, 13) packed states [x_W, v_W, q_WB (w x y z), w_W]; NaN columns for absent groups.
    present : quantity groups the file holds.
    print_floor : quantity -> (K,) rounding of the written values of that quantity in each row (m, m/s,
        rad, rad/s): the norm of the columns' half quanta (orientation: 2 × the quaternion's, an angle),
        plus ½ ulp of single precision for single-precision data.
    single_precision : whether the values look single precision.  unit_roundoff : 2⁻²⁴ or 2⁻⁵³.
    diverged_at_s : time of the first non-finite row (rows from there on are dropped), or None.
    ended_early_s : the last true time when the file stops before the scenario's duration, else None.
    dropped_after_s : rows beyond the scenario's duration were dropped after this time, else None.
    notes : sentences for the report.
    """

    source: str
    t_rec_s: np.ndarray
    t_s: np.ndarray
    n_steps: np.ndarray
    span_steps: np.ndarray
    h_s: float | None
    span_s: np.ndarray
    y: np.ndarray
    present: tuple
    print_floor: dict
    single_precision: bool
    unit_roundoff: float
    time_bound_s: float = 0.0
    diverged_at_s: float | None = None
    lost_orientation_at_s: float | None = None
    ended_early_s: float | None = None
    dropped_after_s: float | None = None
    decimation: int = 1
    notes: list = field(default_factory=list)

    @property
    def n_rows(self) -> int:
        return len(self.t_s)

    @property
    def full_state(self) -> bool:
        return len(self.present) == len(QUANTITY_GROUPS)


# --- precision -------------------------------------------------------------------------------------

def _significant_digits(value: float) -> int:
    """Digits of the shortest decimal that reads back as exactly ``value`` (Python's repr)."""
    mantissa = repr(abs(value)).partition("e")[0].replace(".", "")
    return max(1, len(mantissa.lstrip("0").rstrip("0")))


def written_digits(values, sample: int = 4000) -> tuple:
    """``(S, D)``: the most significant digits and the most decimals any finite non-zero value of
    ``values`` needs to be read back exactly (shortest round-trip decimal), over at most ``sample``
    values spread evenly (a writer's format shows in every value it writes)."""
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v) & (v != 0.0)]
    if v.size == 0:
        return 0, -math.inf
    if v.size > sample:
        v = v[np.linspace(0, v.size - 1, sample).astype(int)]
    digits = np.fromiter((_significant_digits(x) for x in v.tolist()), dtype=np.int64, count=v.size)
    e = np.floor(np.log10(np.abs(v)))
    return int(np.max(digits)), float(np.max(digits - 1 - e))


def printed_half_quantum(values, digits: tuple | None = None) -> tuple:
    """Half the rounding quantum of each written number, and the most significant digits.

    A writer prints either a fixed number of decimals (quantum 10^−D) or a fixed number of significant
    digits (quantum 10^(e − S + 1) for a value of decimal exponent e); ``(S, D)`` come from
    :func:`written_digits` of ``values`` or are given (the same writer's other columns: a constant
    column alone cannot show its precision). Each value gets the larger of the two quanta, so the bound
    holds for either format; with S ≥ 15 the values are full precision (2 ulp). Returns
    ``(half quanta (shape of values; 0 where not finite), S)``.
    """
    v = np.asarray(values, dtype=float)
    max_sig, max_dec = written_digits(v) if digits is None else digits
    if max_sig == 0:
        return np.zeros(v.shape), 0
    a = np.abs(np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0))
    if max_sig >= 15:
        quantum = 2.0 * np.spacing(a)
    else:
        with np.errstate(divide="ignore"):
            e = np.where(a > 0, np.floor(np.log10(np.where(a > 0, a, 1.0))), -np.inf)
        quantum = np.maximum(10.0 ** (-max_dec), 10.0 ** (e - max_sig + 1))
    return np.where(np.isfinite(v), 0.5 * quantum, 0.0), max_sig


def _precision(y, present):
    """(print floor per quantity (K,), single precision?) of the state columns of the present groups."""
    cols = [c for g in present for c in range(BLOCKS[g].start, BLOCKS[g].stop)]
    digits = written_digits(y[:, cols], sample=4000)
    floors = {}
    for g in present:
        sl = BLOCKS[g]
        halves = np.array([printed_half_quantum(y[:, c], digits)[0] for c in range(sl.start, sl.stop)])
        floors[g] = np.linalg.norm(halves, axis=0) * (2.0 if g == "orientation" else 1.0)
    fin = y[:, cols][np.isfinite(y[:, cols])]
    all_f32 = bool(np.all(fin.astype(np.float32).astype(np.float64) == fin))
    single = digits[0] <= tol.CHECK_SINGLE_PRECISION_MAX_DIGITS or all_f32
    if single:   # a single-precision value is ½ ulp from what it stands for, however it is printed
        for g in present:
            mag = np.linalg.norm(np.nan_to_num(y[:, BLOCKS[g]]), axis=1)
            rep = EPS32 * (2.0 * np.maximum(mag, 1.0) if g == "orientation" else mag)
            floors[g] = floors[g] + rep
    return floors, single


# --- times -----------------------------------------------------------------------------------------

def single_precision_time_bound(t_s, n_steps, t_half_quantum: float = 0.0):
    """Largest |t_recorded − n h| (s) a simulator accumulating ``t += h`` in single precision can show
    after ``n`` steps: ``2⁻²⁴ t (n + 3) / 2`` (n additions rounding by ≤ ½ ulp(t) each, averaging t/2,
    plus dt rounded once), plus the rounding of the written time and a double's."""
    t = np.abs(np.asarray(t_s, dtype=float))
    n = np.asarray(n_steps, dtype=float)
    return EPS32 * t * (n + 3.0) / 2.0 + t_half_quantum + 4.0 * EPS64 * t


def _short_decimal(h: float, band: float):
    """The decimal with the fewest significant digits within ``band`` of ``h`` (None if none ≤ 6)."""
    for s in range(1, 7):
        cand = float(f"{h:.{s - 1}e}")
        if abs(cand - h) <= band:
            return cand
    return None


def snap_step(h_est: float, band: float, scenario) -> float:
    """A round value for an estimated step: the scenario's dt or a ladder value, else the shortest
    decimal, when within ``band`` (s) of the estimate; else the estimate itself."""
    for cand in (scenario.dt_s, *scenario.dt_ladder_s):
        if abs(cand - h_est) <= band:
            return float(cand)
    short = _short_decimal(h_est, band)
    return short if short is not None else h_est


def interval_bound(t_end_s, m_steps, t_half_quantum: float = 0.0):
    """Largest error (s) of a recorded row interval spanning ``m`` steps and ending at ``t_end``: m
    single-precision additions (≤ 2⁻²⁴ t each, plus dt rounded: one more) and the two written times."""
    return EPS32 * np.abs(t_end_s) * (np.asarray(m_steps, dtype=float) + 1.0) + 2.0 * t_half_quantum \
        + 4.0 * EPS64 * np.abs(t_end_s)


def _map_rows(source, t, scenario, dt_given, t_half):
    """(h, span_steps) for recorded times ``t`` (K,), or (None, None) for variable steps."""
    d = np.diff(t)
    if dt_given is not None:
        h = float(dt_given)
        m = np.round(d / h)
        bad = np.flatnonzero((m < 1) | (np.abs(d - m * h) > interval_bound(t[1:], np.maximum(m, 1), t_half)))
        if bad.size:
            k = int(bad[0])
            raise CheckError(f"{source}: line {k + 3}: column t: with --dt {h:g} s every row "
                             "interval must be a whole number of steps; t advances "
                             f"{d[k]:.9g} s from line {k + 2} ({d[k] / h:.4g} steps)")
        return h, m.astype(np.int64)
    h0 = float(np.median(d))
    m = np.round(d / h0)
    if np.any(m < 1) or np.any(np.abs(d - m * h0) > tol.CHECK_GRID_SLACK * h0):
        return None, None
    n = np.concatenate([[0.0], np.cumsum(m)])
    h_est = float(t[-1] / n[-1])
    band = float(single_precision_time_bound(t[-1], n[-1], t_half)) / n[-1]
    return snap_step(h_est, band, scenario), m.astype(np.int64)


def _check_jumps(source, t, m):
    typical = float(np.median(m))
    big = np.flatnonzero(m > tol.CHECK_MAX_GAP_FACTOR * typical)
    if big.size:
        k = int(big[0])
        raise CheckError(f"{source}: line {k + 3}: column t: t jumps from {t[k]:.9g} s to {t[k + 1]:.9g} s "
                         f"({int(m[k])} steps where the rows advance {typical:g} step(s) each); "
                         "not a recording of one run")


def prepare_input(traj, scenario, source: str, dt_s: float | None = None) -> CheckInput:
    """Validate a read Trajectory against ``scenario`` and map its rows to steps (see module doc)."""
    t = np.asarray(traj.t_s, dtype=float)
    present = tuple(traj.meta.get("quantities_present", QUANTITY_GROUPS))
    if not any(g in present for g in ("position", "orientation")):
        raise CheckError(f"{source}: header: needs the position (x,y,z) or orientation "
                         f"(qw,qx,qy,qz) columns; found only {', '.join(present)}")
    if len(t) < 2:
        raise CheckError(f"{source}: rows: need at least 2 rows (t = 0 and one step), got {len(t)}")
    notes = []
    t_true, n, m, h, bound_end = _time_grid(source, t, scenario, dt_s, notes)
    span = m * h if h is not None else np.diff(t_true)
    inp = CheckInput(source=source, t_rec_s=t, t_s=t_true, n_steps=n, span_steps=m, h_s=h, span_s=span,
                     y=np.array(traj.y, dtype=float), present=present, print_floor={}, single_precision=False,
                     unit_roundoff=EPS64, time_bound_s=bound_end, notes=notes)
    _cut_non_finite(inp)
    _cut_to_duration(inp, scenario)
    inp.print_floor, inp.single_precision = _precision(inp.y, inp.present)
    inp.unit_roundoff = EPS32 if inp.single_precision else EPS64
    inp.decimation = int(np.median(inp.span_steps)) if len(inp.span_steps) else 1
    steps = np.unique(inp.span_steps)
    if h is not None and steps.size and (steps.size > 1 or steps[0] > 1):
        what = (f"every row spans {int(steps[0])} steps of {h:g} s" if steps.size == 1
                else f"rows span {int(steps.min())}–{int(steps.max())} steps of {h:g} s (rows missing)")
        notes.append(what + ": each one-step comparison advances that many steps")
    return inp


def _time_grid(source, t, scenario, dt_s, notes):
    """(true times n h, step index n, steps per interval m, h or None, drift bound at the end)."""
    t_half = float(np.max(printed_half_quantum(t)[0]))
    h, m = _map_rows(source, t, scenario, dt_s, t_half)
    if h is not None:
        _check_jumps(source, t, m)
        n = np.concatenate([[0], np.cumsum(m)])
        bound = single_precision_time_bound(t, n, t_half)
        if abs(t[0]) > bound[0] + 0.5 * h * 1e-6:
            raise CheckError(f"{source}: line 2: column t: must start at 0 (the scenario's initial state), "
                             f"starts at {t[0]:g} s")
        off = np.abs(t - n * h)
        if not np.any(off > bound + 1e-9 * h):
            if np.max(off) > 16 * EPS64 * max(t[-1], h):
                notes.append(f"the recorded times drift from n·Δt by up to {np.max(off):.2g} s "
                             f"(single-precision accumulation allows {bound[int(np.argmax(off))]:.2g} s "
                             "there): rows were mapped to steps by their intervals and the times n·Δt used")
            return n * h, n, m, h, float(bound[-1])
        k = int(np.argmax(off - bound))
        if dt_s is not None:
            raise CheckError(f"{source}: line {k + 2}: column t: {t[k]:.9g} s is {off[k]:.3g} s from step "
                             f"{int(n[k])} × --dt {h:g} s, beyond the {bound[k]:.2g} s a single-precision "
                             "clock can drift")
        notes.append(f"the recorded times are not a whole number of steps of one Δt (row {k + 1} is "
                     f"{off[k]:.3g} s off): each row interval is taken as one step of its recorded length")
    _check_jumps(source, t, np.maximum(np.round(np.diff(t) / np.median(np.diff(t))), 1))
    if not notes:
        notes.append("the row intervals are not whole multiples of one Δt: each row "
                     "interval is taken as one step of its recorded length (variable steps)")
    if abs(t[0]) > 1e-9 * np.median(np.diff(t)) + t_half:
        raise CheckError(f"{source}: line 2: column t: must start at 0 (the scenario's initial state), "
                         f"starts at {t[0]:g} s")
    return t - t[0], np.arange(len(t)), np.ones(len(t) - 1, dtype=np.int64), None, 0.0


def _zero_quaternion_rows(inp):
    if "orientation" not in inp.present:
        return np.zeros(len(inp.t_s), dtype=bool)
    qn = np.linalg.norm(inp.y[:, Q], axis=1)
    return ~(qn > tol.CHECK_ZERO_QUATERNION)


def _cut_non_finite(inp):
    """Drop rows from the first non-finite or blown-up state (or lost orientation) on; record when.

    A component beyond reference_sim.simulate.BLOWUP_LIMIT counts as a blow-up, as in every run."""
    from reference_sim.simulate import BLOWUP_LIMIT, bad_rows
    cols = np.concatenate([np.arange(BLOCKS[g].start, BLOCKS[g].stop) for g in inp.present])
    finite = ~bad_rows(inp.y[:, cols])
    zero_q = _zero_quaternion_rows(inp)
    if zero_q[0] and finite[0]:
        raise CheckError(f"{inp.source}: line 2: columns qw,qx,qy,qz: the quaternion is zero, "
                         "not an orientation (w, x, y, z of a unit quaternion expected)")
    if not finite[0]:
        bad = [c for c in cols if not abs(inp.y[0, c]) <= BLOWUP_LIMIT]
        from cross_checks.core.trajectory import COLUMNS
        raise CheckError(f"{inp.source}: line 2: column {COLUMNS[bad[0] + 1]}: the initial state "
                         f"must be finite (and below {BLOWUP_LIMIT:g}), got {inp.y[0, bad[0]]}")
    good = finite & ~zero_q
    if good.all():
        return
    k = int(np.argmin(good))
    if not finite[k]:
        inp.diverged_at_s = float(inp.t_s[k])
    else:
        inp.lost_orientation_at_s = float(inp.t_s[k])
    _keep(inp, k)


def _keep(inp, k):
    """Keep rows [0, k)."""
    inp.t_rec_s, inp.t_s, inp.n_steps, inp.y = inp.t_rec_s[:k], inp.t_s[:k], inp.n_steps[:k], inp.y[:k]
    inp.span_steps, inp.span_s = inp.span_steps[:k - 1], inp.span_s[:k - 1]


def _cut_to_duration(inp, scenario):
    T = scenario.duration_s
    h = inp.h_s if inp.h_s is not None else float(np.median(inp.span_s)) if len(inp.span_s) else T
    slack = tol.CHECK_DURATION_SLACK_STEPS * h
    beyond = np.flatnonzero(inp.t_s > T + slack)
    if beyond.size:
        k = int(beyond[0])
        inp.dropped_after_s = float(inp.t_s[k - 1])
        inp.notes.append(f"the file runs to t = {inp.t_s[-1]:.6g} s, beyond the scenario's "
                         f"duration {T:g} s: it is compared up to "
                         f"t = {inp.t_s[k - 1]:.6g} s ({len(inp.t_s) - k} later rows ignored)")
        _keep(inp, k)
    if inp.diverged_at_s is None and inp.lost_orientation_at_s is None and inp.t_s[-1] < T - slack:
        inp.ended_early_s = float(inp.t_s[-1])


def describe_time(inp) -> str:
    """One phrase: rows, time span, step."""
    if inp.h_s is None:
        return f"{inp.n_rows} rows, t = 0 … {inp.t_s[-1]:.6g} s, variable steps"
    d = inp.decimation
    per = (f"one row per step of Δt = {inp.h_s:g} s" if d == 1
           else f"one row every {d} steps of Δt = {inp.h_s:g} s")
    return f"{inp.n_rows} rows, t = 0 … {inp.t_s[-1]:.6g} s, {per}"
