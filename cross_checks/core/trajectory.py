"""Trajectories: the CSV + sidecar JSON of docs/trajectory.md.

CSV columns (written in this order, read by name in any order): ``t,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz`` —
time (s); COM position (m, world); COM velocity (m/s, world); orientation body→world (w, x, y, z); angular
velocity (rad/s, WORLD). Metadata goes in ``<name>.json`` next to ``<name>.csv``.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cross_checks.core.files import atomic_write_text, json_default
from reference_sim.state import Q, V, W, X

__all__ = ["Trajectory", "COLUMNS", "QUANTITY_GROUPS", "TrajectoryError", "read_columns", "sidecar_path"]

COLUMNS = ("t", "x", "y", "z", "vx", "vy", "vz", "qw", "qx", "qy", "qz", "wx", "wy", "wz")


#: Column groups of the CSV contract, by quantity (each group is all-or-nothing in a file).
QUANTITY_GROUPS = ("position", "velocity", "orientation", "angular_velocity")
_GROUP_COLUMNS = {
    "position": ("x", "y", "z"),
    "velocity": ("vx", "vy", "vz"),
    "orientation": ("qw", "qx", "qy", "qz"),
    "angular_velocity": ("wx", "wy", "wz"),
}


class TrajectoryError(ValueError):
    """A trajectory file that does not follow the contract; message names file, field and reason."""


def _limits():
    from cross_checks.core import tolerances as tol
    max_rows = int(tol.JOB_MEMORY_LIMIT_BYTES // tol.BYTES_PER_RECORDED_STEP) + 1
    return max_rows, tol.CSV_MAX_LINE_BYTES, tol.CSV_MAX_BYTES


def _read_bounded(name: str, path, max_rows: int, max_line: int, max_bytes: int) -> bytes:
    """The file's bytes, read in chunks and refused as soon as it cannot be a trajectory: a line
    longer than ``max_line`` bytes (``/dev/zero``, a binary file), more than ``max_rows`` data rows
    (no run of the limits records more steps), or more than ``max_bytes`` in all. Memory stays bounded
    by what a valid file holds."""
    chunks, size, lines, carry = [], 0, 0, 0   # carry: bytes of the line still open at the chunk's start
    try:
        with open(path, "rb") as fh:
            while True:
                chunk = fh.read(1 << 20)
                if not chunk:
                    break
                size += len(chunk)
                if size > max_bytes:
                    raise TrajectoryError(f"{name}: larger than {max_bytes / 2 ** 30:.3g} GiB: no "
                                          "trajectory within rbcheck's limits is (docs/hardening.md)")
                parts = chunk.split(b"\n")
                lengths = [carry + len(parts[0])] + [len(p) for p in parts[1:]]
                worst = max(range(len(lengths)), key=lengths.__getitem__)
                if lengths[worst] > max_line:
                    raise TrajectoryError(f"{name}: line {lines + worst + 1}: longer "
                                          f"than {max_line} bytes: not a trajectory CSV")
                carry = lengths[-1]
                lines += len(parts) - 1
                if lines > max_rows + 1:
                    raise TrajectoryError(f"{name}: rows: more than {max_rows} rows; no run "
                                          "within rbcheck's limits records more steps "
                                          f"({max_rows - 1} per run, docs/hardening.md)")
                chunks.append(chunk)
    except OSError as exc:
        raise TrajectoryError(f"{name}: cannot read: {exc.strerror or exc}") from None
    return b"".join(chunks)


def sidecar_path(csv_path) -> Path:
    return Path(csv_path).with_suffix(".json")


@dataclass
class Trajectory:
    """A recorded trajectory of one body.

    t_s : (T,) s.  y : (T, 13) packed [x_W (m), v_W (m/s), q_WB (w, x, y, z), w_W (rad/s, world)].
    meta : engine, version, variant, dt, scenario name and hash, status, diverged_at_s, ...
    """

    t_s: np.ndarray
    y: np.ndarray
    meta: dict = field(default_factory=dict)

    @property
    def x_W(self):
        return self.y[:, X]

    @property
    def v_W(self):
        return self.y[:, V]

    @property
    def q_WB(self):
        return self.y[:, Q]

    @property
    def w_W(self):
        return self.y[:, W]

    @property
    def diverged_at_s(self):
        return self.meta.get("diverged_at_s")

    def to_csv_text(self) -> str:
        data = np.column_stack([self.t_s, self.y])
        lines = [",".join(COLUMNS)]
        lines += [",".join(repr(float(v)) for v in row) for row in data]
        return "\n".join(lines) + "\n"

    def write(self, csv_path) -> None:
        """Write the CSV and its sidecar JSON (atomically each; the JSON last)."""
        csv_path = Path(csv_path)
        atomic_write_text(csv_path, self.to_csv_text())
        atomic_write_text(sidecar_path(csv_path),
                          json.dumps(self.meta, indent=2, sort_keys=True, default=json_default) + "\n")

    @classmethod
    def read(cls, csv_path, *, require: tuple = QUANTITY_GROUPS) -> Trajectory:
        """Read a trajectory CSV (and its sidecar JSON when present). Raises TrajectoryError.

        Columns are read by NAME (:func:`read_columns`): any order, extra columns ignored. ``require``
        names the quantity groups that must be present (default: all four); a group that is allowed
        to be absent comes back as NaN columns, and ``meta["quantities_present"]`` lists the groups
        the file holds.
        """
        csv_path = Path(csv_path)
        t, y, present = read_columns(csv_path, require=require)
        meta = {}
        sc = sidecar_path(csv_path)
        if sc.is_file():
            try:
                meta = json.loads(sc.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                raise TrajectoryError(f"{sc}: cannot parse sidecar JSON: {exc}") from None
            if not isinstance(meta, dict):
                raise TrajectoryError(f"{sc}: sidecar JSON must be an object, got {type(meta).__name__}")
        meta = dict(meta)
        meta["quantities_present"] = list(present)
        return cls(t, y, meta)


#: Rows parsed at a time by the fast path: the Python strings and floats of a block (~1 KB a row) are
#: the parse's peak memory beyond the text and the array, instead of those of the whole file.
_FAST_BLOCK_ROWS = 65536


def _fast_table(text: str):
    """``(header cells, (N, ncol) float array)`` when the CSV is plain — no quotes or NULs, every
    non-blank line with the header's number of fields, every field a number for ``float()`` — else
    None. The same strings go through the same ``float()`` as the general path, so where this
    succeeds the values are identical; anything else is left to the general path and its messages."""
    if '"' in text or "\x00" in text:
        return None
    lines = text.split("\n")
    if not all(map(str.strip, lines)):  # (C-speed checks: this runs on every row of every engine run)
        lines = [ln for ln in lines if ln.strip()]
    if len(lines) < 2:
        return None
    ncol = lines[0].count(",") + 1
    body = lines[1:]
    counts = list(map(str.count, body, [","] * len(body)))
    if min(counts) != ncol - 1 or max(counts) != ncol - 1:
        return None
    values = np.empty((len(body), ncol))
    for i in range(0, len(body), _FAST_BLOCK_ROWS):   # in blocks: the Python strings of one block at a time
        block = body[i:i + _FAST_BLOCK_ROWS]
        try:
            values[i:i + len(block)] = np.array(list(map(float, ",".join(block).split(","))),
                                                dtype=float).reshape(len(block), ncol)
        except ValueError:
            return None
    return lines[0].split(","), values


def read_columns(csv_path, *, require: tuple = QUANTITY_GROUPS, _fast: bool = True):
    """Parse a trajectory CSV by column NAME.

    The header is required; names are matched case-sensitively after stripping spaces; columns may
    come in any order and unknown columns are ignored (docs/trajectory.md: ``qw,qx,qy,qz`` name the quaternion
    whatever their order). ``t`` is required, and every group of ``require``; a group is present only
    with all its columns. Times must be finite and strictly increasing (they may carry single-precision
    rounding: interpreting them is the caller's business). State values may be non-finite (a diverged
    run): callers decide what that means.

    Returns ``(t_s (T,), y (T, 13), present)`` with ``y`` packed [x_W, v_W, q_WB (w x y z), w_W] and NaN
    in the columns of absent groups; ``present`` is the tuple of groups found, in QUANTITY_GROUPS order.
    Raises TrajectoryError naming the file, the line or column, and the reason.
    """
    name = str(csv_path)
    raw = _read_bounded(name, csv_path, *_limits())
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise TrajectoryError(f"{name}: cannot read: {exc}") from None
    del raw
    fast = _fast_table(text) if _fast else None  # (header cells, (N, ncol) floats) of a plain numeric CSV
    rows = [fast[0]] if fast is not None else _csv_rows(name, text)
    header = [h.strip() for h in rows[0]]
    index = _header_index(name, header)
    present = _present_groups(name, index, require)
    wanted = [("t", index["t"])] + [(c, index[c]) for g in present for c in _GROUP_COLUMNS[g]]
    pos = {c: COLUMNS.index(c) for c in COLUMNS}
    if fast is not None:
        data = np.full((len(fast[1]), len(COLUMNS)), np.nan)
        for c, i in wanted:
            data[:, pos[c]] = fast[1][:, i]
    else:
        data = _parse_rows(name, rows[1:], len(header), wanted, pos)
    if len(data) == 0:
        raise TrajectoryError(f"{name}: rows: no data rows")
    _check_times(name, data[:, 0])
    return data[:, 0], data[:, 1:], tuple(present)


def _csv_rows(name: str, text: str) -> list:
    """The non-blank rows of a CSV text (the readable path, for files the fast parser does not take)."""
    import csv
    import io
    try:
        rows = [r for r in csv.reader(io.StringIO(text)) if any(c.strip() for c in r)]
    except csv.Error as exc:
        raise TrajectoryError(f"{name}: cannot parse as CSV: {exc}") from None
    if not rows:
        raise TrajectoryError(f"{name}: header: file is empty")
    return rows


def _header_index(name: str, header: list) -> dict:
    """Column name → its first index; a contract column twice, or no ``t``, is an error."""
    index: dict[str, int] = {}
    for i, h in enumerate(header):
        if h in index and h in COLUMNS:
            raise TrajectoryError(f"{name}: header: column {h!r} appears twice")
        index.setdefault(h, i)
    if "t" not in index:
        raise TrajectoryError(f"{name}: header: no column 't' (expected the columns {','.join(COLUMNS)}, "
                              f"by name, any order; got {','.join(header)[:120]})")
    return index


def _present_groups(name: str, index: dict, require) -> list:
    """The quantity groups whose columns are all in the header (in QUANTITY_GROUPS order); a partial group,
    a missing required one, or none at all is an error."""
    present = []
    for g in QUANTITY_GROUPS:
        cols = _GROUP_COLUMNS[g]
        have = [c for c in cols if c in index]
        if have and len(have) < len(cols):
            raise TrajectoryError(f"{name}: header: {g} needs all of {','.join(cols)}; "
                                  f"missing {','.join(c for c in cols if c not in index)}")
        if have:
            present.append(g)
        elif g in require:
            raise TrajectoryError(f"{name}: header: {g} columns {','.join(cols)} missing "
                                  f"(expected {','.join(COLUMNS)}, by name, any order)")
    if not present:
        raise TrajectoryError(f"{name}: header: no state columns (expected "
                              f"{','.join(COLUMNS)}, by name, any order)")
    return present


def _parse_rows(name: str, rows: list, ncol: int, wanted: list, pos: dict):
    """(N, len(COLUMNS)) floats of the ``wanted`` (column, index) cells, NaN elsewhere; line numbers in
    errors count the header as line 1."""
    data = np.full((len(rows), len(COLUMNS)), np.nan)
    for k, row in enumerate(rows):
        line = k + 2
        if len(row) != ncol:
            raise TrajectoryError(f"{name}: line {line}: expected {ncol} "
                                  f"values (as in the header), got {len(row)}")
        for c, i in wanted:
            cell = row[i].strip()
            try:
                data[k, pos[c]] = float(cell)
            except ValueError:
                raise TrajectoryError(
                    f"{name}: line {line}: column {c}: not a number: {cell[:40]!r}") from None
    return data


def _check_times(name: str, t) -> None:
    """Times finite and strictly increasing."""
    if not np.all(np.isfinite(t)):
        k = int(np.argmin(np.isfinite(t)))
        raise TrajectoryError(f"{name}: line {k + 2}: column t: time must be finite, got {t[k]}")
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0)) + 1
        raise TrajectoryError(f"{name}: line {k + 2}: column t: times must strictly increase "
                              f"({float(t[k - 1])!r} then {float(t[k])!r})")


