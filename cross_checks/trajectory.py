"""Trajectories: the CSV + sidecar JSON contract of DESIGN.md.

CSV columns, in order: ``t,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz`` — time (s); COM position (m, world);
COM velocity (m/s, world); orientation body→world (w, x, y, z); angular velocity (rad/s, WORLD).
Metadata goes in ``<name>.json`` next to ``<name>.csv``.
"""
from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from reference_sim.state import Q, V, W, X

__all__ = ["Trajectory", "COLUMNS", "TrajectoryError", "sidecar_path", "atomic_write_text", "json_default"]

COLUMNS = ("t", "x", "y", "z", "vx", "vy", "vz", "qw", "qx", "qy", "qz", "wx", "wy", "wz")


class TrajectoryError(ValueError):
    """A trajectory file that does not follow the contract; message names file, field and reason."""


def sidecar_path(csv_path) -> Path:
    p = Path(csv_path)
    return p.with_suffix(".json")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same directory and a rename, so a
    reader never sees a half-written file and an interrupted write leaves the old one intact."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent or ".")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp creates 0600; give the file the user's usual mode
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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
        atomic_write_text(sidecar_path(csv_path), json.dumps(self.meta, indent=2, sort_keys=True, default=json_default) + "\n")

    @classmethod
    def read(cls, csv_path) -> "Trajectory":
        """Read a contract CSV (and its sidecar JSON when present). Raises TrajectoryError."""
        csv_path = Path(csv_path)
        name = str(csv_path)
        try:
            text = csv_path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise TrajectoryError(f"{name}: cannot read: {exc}") from None
        lines = [ln for ln in text.splitlines() if ln.strip()]
        if not lines:
            raise TrajectoryError(f"{name}: header: file is empty")
        header = [h.strip() for h in lines[0].split(",")]
        if tuple(header) != COLUMNS:
            raise TrajectoryError(f"{name}: header: expected {','.join(COLUMNS)}, got {lines[0][:120]}")
        rows = []
        for i, ln in enumerate(lines[1:], start=2):
            parts = ln.split(",")
            if len(parts) != len(COLUMNS):
                raise TrajectoryError(f"{name}: line {i}: expected {len(COLUMNS)} values, got {len(parts)}")
            try:
                rows.append([float(p) for p in parts])
            except ValueError:
                raise TrajectoryError(f"{name}: line {i}: not a number in {ln[:80]!r}") from None
        if not rows:
            raise TrajectoryError(f"{name}: rows: no data rows")
        data = np.array(rows)
        if not np.all(np.isfinite(data[:, 0])) or np.any(np.diff(data[:, 0]) <= 0):
            raise TrajectoryError(f"{name}: t: times must be finite and strictly increasing")
        meta = {}
        sc = sidecar_path(csv_path)
        if sc.is_file():
            try:
                meta = json.loads(sc.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                raise TrajectoryError(f"{sc}: cannot parse sidecar JSON: {exc}") from None
        return cls(data[:, 0], data[:, 1:], meta)


def json_default(o):
    """``json.dumps(default=...)`` for NumPy scalars and arrays (shared by every JSON rbcheck writes)."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
