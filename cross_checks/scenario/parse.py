"""Scenario files (TOML, docs/scenario.md): load, validate, and turn into a reference_sim Problem.

Every validation error is a :class:`ScenarioError` whose message names the file, the field and the
reason, e.g. ``my.toml: body.mass: must be > 0, got -1``.
"""
from __future__ import annotations

import hashlib
import json
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from cross_checks.core.names import NAME_RE, did_you_mean, unknown_key_reason
from cross_checks.core.tolerances import MAX_NAME_CHARS, MIN_LADDER_RATIO
from reference_sim.body import RigidBody, check_inertia
from reference_sim.forces import FRAMES, ForceModel, PointForce, Spring, Torque
from reference_sim.quaternion import quat_from_euler_zxy, rotate
from reference_sim.state import Problem, State

__all__ = ["Scenario", "ScenarioError", "load_scenario", "parse_scenario", "catalog_names", "catalog_path",
           "REFERENCE_KINDS", "SCENARIO_KINDS", "long_run_names"]

#: How a scenario's reference solution is obtained: "analytic" (a closed form of reference_sim.analytic
#: must exist for it), "ground_truth" (DOP853 at reference_sim.ground_truth.GROUND_TRUTH_RTOL), or "auto"
#: (analytic when one exists).
REFERENCE_KINDS = ("auto", "analytic", "ground_truth")
#: What a scenario is for: "convergence" (the default: its Δt ladder, errors against its reference) or
#: "long_run" (one Δt over thousands of periods: conservation and the drift towards the intermediate axis).
SCENARIO_KINDS = ("convergence", "long_run")


class ScenarioError(ValueError):
    """Bad scenario input; ``str()`` is ``FILE: FIELD: REASON``."""

    def __init__(self, source: str, field_: str, reason: str):
        self.source, self.field, self.reason = source, field_, reason
        super().__init__(f"{source}: {field_}: {reason}" if field_ else f"{source}: {reason}")


@dataclass(frozen=True, eq=False)
class Scenario:
    """A validated scenario.

    name, description : identity (name matches ``[a-z0-9_]+``).
    duration_s, dt_s : simulated time and default step, s.
    dt_ladder_s : steps for convergence studies, s (defaults to ``(dt_s,)``).
    reference : one of REFERENCE_KINDS.
    problem : the reference_sim Problem (body at its COM, forces, initial state with world ω).
    source : file path or "catalog:NAME".
    raw : the parsed TOML (for hashing and provenance).
    com_offset_B_m : for a body given as ``particles``, where their COM is in the particles' own
        coordinates (m); every body point of the file (spring ``attach``, force ``point``) is in those
        coordinates and was shifted by it, so the Problem's points are from the COM. None otherwise.
    kind : one of SCENARIO_KINDS: ``"convergence"`` (a Δt ladder judged against a reference) or
        ``"long_run"`` (one Δt over a long duration, judged on what it conserves: docs/scenario.md,
        "Long runs").
    body_com_B_m : for a body given with ``com`` or ``parts``, its COM in the body's own frame, from the
        frame's origin (m, body axes): the origin is not at the COM (the COM-offset invariance check,
        docs/invariance.md). The file's initial position and velocity are the origin's and its body points
        are from the origin; the Problem's are the COM's (converted here). None: the origin is at the COM.
    body_parts : for a body given as ``parts``, its welded parts (reference_sim.body.BodyPart, COMs from
        the body frame's origin); the Problem's body is their composite. Empty otherwise.
    """

    name: str
    description: str
    duration_s: float
    dt_s: float
    dt_ladder_s: tuple
    reference: str
    problem: Problem
    source: str
    raw: dict = field(repr=False)
    com_offset_B_m: np.ndarray | None = None
    kind: str = "convergence"
    body_com_B_m: np.ndarray | None = None
    body_parts: tuple = ()

    @property
    def long_run(self) -> bool:
        """Whether this is a long run (kind ``"long_run"``): the sweep's long-run stage runs it, at ``dt_s``
        only, and measures its conservation (cross_checks.analysis.long_run) instead of its convergence."""
        return self.kind == "long_run"

    @property
    def content_hash(self) -> str:
        """SHA-256 (first 16 hex digits) of the canonical JSON of the parsed file: same physics, same hash."""
        blob = json.dumps(self.raw, sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(blob).hexdigest()[:16]

    def n_steps(self, dt_s: float | None = None, duration_s: float | None = None) -> int:
        dt = self.dt_s if dt_s is None else dt_s
        T = self.duration_s if duration_s is None else duration_s
        return int(round(T / dt))


# --- catalog ---------------------------------------------------------------------------------------

def _catalog_dir():
    return resources.files("cross_checks.scenario") / "catalog"


def _long_run_dir():
    return _catalog_dir() / "long_runs"


def catalog_names() -> list[str]:
    """Names of the built-in convergence scenarios (``catalog/*.toml``), sorted: the default sweep's."""
    return sorted(p.name[:-5] for p in _catalog_dir().iterdir() if p.name.endswith(".toml"))


def long_run_names() -> list[str]:
    """Names of the built-in long runs (``catalog/long_runs/*.toml``, each ``kind = "long_run"``), sorted:
    what ``rbcheck sweep --long`` adds (docs/scenario.md, "Long runs")."""
    return sorted(p.name[:-5] for p in _long_run_dir().iterdir() if p.name.endswith(".toml"))


def catalog_path(name: str):
    """The file of the built-in scenario ``name``: a convergence scenario or a long run."""
    if name in long_run_names():
        return _long_run_dir() / f"{name}.toml"
    return _catalog_dir() / f"{name}.toml"


def load_scenario(spec: str | Path) -> Scenario:
    """Load a catalog scenario by name, or a TOML file by path. Raises ScenarioError on bad input."""
    spec_s = str(spec)
    if NAME_RE.match(spec_s) and not spec_s.endswith(".toml") and not Path(spec_s).exists():
        known = catalog_names() + long_run_names()
        if spec_s not in known:
            raise ScenarioError(spec_s, "",
                                f"no catalog scenario of that name{did_you_mean(spec_s, known)} "
                                f"and no such file (catalog: {', '.join(known)})")
        text = catalog_path(spec_s).read_text(encoding="utf-8")
        return parse_scenario(text, source=f"catalog:{spec_s}")
    path = Path(spec_s)
    if not path.is_file():
        raise ScenarioError(spec_s, "", "no such file (and not a catalog scenario name)")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(spec_s, "", f"cannot read: {exc}") from None
    return parse_scenario(text, source=spec_s)


# --- parsing helpers --------------------------------------------------------------------------------

class _Reader:
    def __init__(self, source):
        self.source = source

    def err(self, fld, reason):
        return ScenarioError(self.source, fld, reason)

    def table(self, d, fld, required=True):
        if fld.split(".")[-1] not in d:
            if required:
                raise self.err(fld, "missing section")
            return {}
        v = d[fld.split(".")[-1]]
        if not isinstance(v, dict):
            raise self.err(fld, f"must be a table [{fld}], got {type(v).__name__}")
        return v

    def check_keys(self, d, allowed, where):
        for k in d:
            if k not in allowed:
                raise self.err(f"{where}.{k}" if where else k, unknown_key_reason(k, allowed))

    def number(self, d, key, fld, *, default=None, positive=False, nonneg=False, required=False):
        if key not in d:
            if required:
                raise self.err(fld, "missing (required)")
            return default
        v = d[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.err(fld, f"must be a number, got {_show(v)}")
        v = float(v)
        if not math.isfinite(v):
            raise self.err(fld, f"must be finite, got {v}")
        if positive and not v > 0:
            raise self.err(fld, f"must be > 0, got {v:g}")
        if nonneg and v < 0:
            raise self.err(fld, f"must be >= 0, got {v:g}")
        return v

    def vector(self, d, key, fld, n, *, default=None, required=False):
        if key not in d:
            if required:
                raise self.err(fld, "missing (required)")
            return None if default is None else np.array(default, dtype=float)
        v = d[key]
        if not isinstance(v, list):
            raise self.err(fld, f"must be a list of {n} numbers, got {_show(v)}")
        if len(v) != n:
            raise self.err(fld, f"must have {n} numbers, got {len(v)}")
        return np.array([self.number({"v": e}, "v", f"{fld}[{i}]") for i, e in enumerate(v)])

    def string(self, d, key, fld, *, default=None, choices=None):
        if key not in d:
            return default
        v = d[key]
        if not isinstance(v, str):
            raise self.err(fld, f"must be a string, got {_show(v)}")
        if choices is not None and v not in choices:
            raise self.err(fld, f"must be one of {', '.join(repr(c) for c in choices)}, got {v!r}")
        return v

    def array_of_tables(self, d, key, fld):
        if key not in d:
            return []
        v = d[key]
        if not isinstance(v, list) or not all(isinstance(e, dict) for e in v):
            raise self.err(fld, f"must be an array of tables [[{fld}]]")
        return v


def _show(v):
    s = repr(v)
    return s if len(s) <= 40 else s[:37] + "..."


_TOP = {"name", "description", "kind", "duration", "dt", "dt_ladder", "reference", "body", "initial",
        "forces"}
_BODY = {"mass", "inertia", "particles", "com", "parts"}
_PART = {"mass", "com", "inertia"}
_INITIAL = {"position", "velocity", "orientation", "euler_zxy_deg",
            "angular_velocity", "angular_velocity_body"}
_FORCES = {"gravity", "linear_drag", "velocity_decay", "angular_velocity_decay", "spring", "point", "torque"}
_SPRING = {"anchor", "attach", "stiffness", "rest_length"}
_POINT = {"force", "point", "frame"}
_TORQUE = {"torque", "frame"}


def parse_scenario(text: str, source: str = "<string>") -> Scenario:
    """Parse and validate scenario TOML text. ``source`` names the file in error messages."""
    r = _Reader(source)
    raw = _load_toml(text, source)
    r.check_keys(raw, _TOP, "")
    name, description, duration, dt, ladder, reference = _parse_timing(r, raw)
    kind = r.string(raw, "kind", "kind", default="convergence", choices=SCENARIO_KINDS)
    body, com_offset, body_com, parts = _parse_body(r, raw)
    shift = com_offset if body_com is None else body_com
    initial = _parse_initial(r, raw)
    if body_com is not None:   # the file's initial state is the origin's; the COM's: x_o + R c, v_o + ω × R c
        from reference_sim.body import com_state
        y = com_state(initial.x_W, initial.v_W, initial.q_WB, initial.w_W, body_com)
        initial = State(y[0:3], y[3:6], y[6:10], y[10:13])
    problem = Problem(body, _parse_forces(r, raw, dt, shift), initial)
    sc = Scenario(name=name, description=description, duration_s=duration, dt_s=dt, dt_ladder_s=ladder,
                  reference=reference, problem=problem, source=source, raw=raw, com_offset_B_m=com_offset,
                  kind=kind, body_com_B_m=body_com, body_parts=parts)
    if sc.long_run:
        _check_long_run(r, raw, sc)
    _check_scenario(r, sc)
    return sc


def _load_toml(text: str, source: str) -> dict:
    """The TOML document as a dict; a syntax error or absurd nesting is a ScenarioError."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(source, "", f"TOML syntax error: {exc}") from None
    except RecursionError:
        raise ScenarioError(source, "", "TOML nested too deeply (arrays or tables inside each other hundreds "
                                        "of levels deep); a scenario needs at most 3 levels") from None


def _parse_timing(r, raw):
    """name, description, duration (s), dt (s), the Δt ladder (s, decreasing) and the reference kind."""
    if "name" not in raw:
        raise r.err("name", "missing (required)")
    name = r.string(raw, "name", "name")
    if not NAME_RE.match(name):
        raise r.err("name",
                    f"must match [a-z0-9_]+ (lower-case letters, digits, underscore), got {_show(name)}")
    if len(name) > MAX_NAME_CHARS:
        raise r.err("name",
                    f"must have at most {MAX_NAME_CHARS} characters (it names files), got {len(name)}")
    description = r.string(raw, "description", "description", default="")
    duration = r.number(raw, "duration", "duration", required=True, positive=True)
    dt = r.number(raw, "dt", "dt", required=True, positive=True)
    if dt > duration:
        raise r.err("dt", f"must be <= duration ({duration:g} s), got {dt:g}")
    ladder = (dt,)
    if "dt_ladder" in raw:
        lv = raw["dt_ladder"]
        if not isinstance(lv, list) or not lv:
            raise r.err("dt_ladder", f"must be a non-empty list of numbers, got {_show(lv)}")
        vals = []
        for i, _ in enumerate(lv):
            v = r.number({"v": lv[i]}, "v", f"dt_ladder[{i}]", positive=True)
            if v > duration:
                raise r.err(f"dt_ladder[{i}]", f"must be <= duration ({duration:g} s), got {v:g}")
            vals.append(v)
        if len(set(vals)) != len(vals):
            raise r.err("dt_ladder", "has repeated values")
        ladder = tuple(sorted(vals, reverse=True))
        _check_ladder_spacing(r, vals, ladder)
    reference = r.string(raw, "reference", "reference", default="auto", choices=REFERENCE_KINDS)

    return name, description, duration, dt, ladder, reference


def _parse_body(r, raw):
    """``(body, com_offset, body_com, parts)``: the rigid body (mass, inertia in body axes about the COM); for
    a particle body, the COM in the particles' coordinates (m; else None); for a body given with ``com`` or
    ``parts``, the COM in the body's own frame from its origin (m; else None); the welded parts (BodyPart;
    else empty)."""
    b = r.table(raw, "body")
    r.check_keys(b, _BODY, "body")
    com_offset = None
    if "parts" in b:
        for other in ("mass", "inertia", "particles", "com"):
            if other in b:
                raise r.err(f"body.{other}", "give either parts (each with its mass, com and inertia) or "
                                             "mass + inertia (+ com) or particles, not both")
        return _parse_parts(r, b)
    body_com = None
    if "com" in b:
        if "particles" in b:
            raise r.err("body.com", "a particle body's COM is where its particles put it; give com only "
                                    "with mass + inertia")
        body_com = r.vector(b, "com", "body.com", 3)
    if "particles" in b:
        if "mass" in b or "inertia" in b:
            raise r.err("body.particles", "give either particles or mass + inertia, not both")
        P = b["particles"]
        if not isinstance(P, list) or not P:
            raise r.err("body.particles", "must be a non-empty list of [m, x, y, z]")
        rows = [r.vector({"p": p}, "p", f"body.particles[{i}]", 4) for i, p in enumerate(P)]
        for i, row in enumerate(rows):
            if not row[0] > 0:
                raise r.err(f"body.particles[{i}]", f"mass must be > 0, got {row[0]:g}")
        try:
            body, com_offset = RigidBody.from_particles(np.array(rows))
        except ValueError as exc:
            raise r.err("body.particles", f"the inertia of these particles {exc} (e.g. all on one "
                                          "line: a rod has no inertia about its axis)") from None
    else:
        mass = r.number(b, "mass", "body.mass", required=True, positive=True)
        if "inertia" not in b:
            raise r.err("body.inertia", "missing (required unless body.particles is given)")
        I = b["inertia"]
        shape_msg = "must be 3 principal moments [A, B, C] or a 3x3 tensor [[..], [..], [..]] (kg m^2)"
        if not isinstance(I, list):
            raise r.err("body.inertia", f"{shape_msg}, got {_show(I)}")
        if any(isinstance(e, list) for e in I):
            if len(I) != 3 or not all(isinstance(e, list) for e in I):
                raise r.err("body.inertia", f"{shape_msg}, got {len(I)} rows")
            inertia = np.array([r.vector({"v": row}, "v", f"body.inertia[{i}]", 3)
                                for i, row in enumerate(I)])
        else:
            inertia = r.vector(b, "inertia", "body.inertia", 3)
        try:
            inertia = check_inertia(inertia)
        except ValueError as exc:
            raise r.err("body.inertia", str(exc)) from None
        body = RigidBody(mass, inertia)

    return body, com_offset, body_com, ()


def _inertia(r, d, fld):
    """An inertia of the file at ``d[inertia]``: 3 principal moments or a 3×3 tensor (kg m²), checked."""
    shape_msg = "must be 3 principal moments [A, B, C] or a 3x3 tensor [[..], [..], [..]] (kg m^2)"
    if "inertia" not in d:
        raise r.err(fld, "missing (required)")
    I = d["inertia"]
    if not isinstance(I, list):
        raise r.err(fld, f"{shape_msg}, got {_show(I)}")
    if any(isinstance(e, list) for e in I):
        if len(I) != 3 or not all(isinstance(e, list) for e in I):
            raise r.err(fld, f"{shape_msg}, got {len(I)} rows")
        inertia = np.array([r.vector({"v": row}, "v", f"{fld}[{i}]", 3) for i, row in enumerate(I)])
    else:
        inertia = r.vector(d, "inertia", fld, 3)
    try:
        return check_inertia(inertia)
    except ValueError as exc:
        raise r.err(fld, str(exc)) from None


def _parse_parts(r, b):
    """A body given as welded parts (``[[body.parts]]``: mass, com from the body frame's origin, inertia
    about the part's own COM): the composite body, its COM in the body frame, and the parts."""
    from cross_checks.core.tolerances import MAX_BODY_PARTS
    from reference_sim.body import BodyPart, compose_parts
    entries = r.array_of_tables(b, "parts", "body.parts")
    if not 1 <= len(entries) <= MAX_BODY_PARTS:
        raise r.err("body.parts", f"must list 1 to {MAX_BODY_PARTS} parts, got {len(entries)}")
    parts = []
    for i, d in enumerate(entries):
        where = f"body.parts[{i}]"
        r.check_keys(d, _PART, where)
        parts.append(BodyPart(r.number(d, "mass", f"{where}.mass", required=True, positive=True),
                              r.vector(d, "com", f"{where}.com", 3, default=[0.0, 0.0, 0.0]),
                              _inertia(r, d, f"{where}.inertia")))
    mass, com, inertia = compose_parts(parts)
    try:
        body = RigidBody(mass, inertia)
    except ValueError as exc:
        raise r.err("body.parts", f"the inertia these parts make {exc}") from None
    return body, None, com, tuple(parts)


def _parse_initial(r, raw) -> State:
    """The initial state: x (m, world), v (m/s, world), q (w, x, y, z; body to world), ω (rad/s, world)."""
    ini = r.table(raw, "initial")
    r.check_keys(ini, _INITIAL, "initial")
    x0 = r.vector(ini, "position", "initial.position", 3, default=[0.0, 0.0, 0.0])
    v0 = r.vector(ini, "velocity", "initial.velocity", 3, default=[0.0, 0.0, 0.0])
    if "orientation" in ini and "euler_zxy_deg" in ini:
        raise r.err("initial.orientation", "give exactly one of orientation and euler_zxy_deg")
    if "euler_zxy_deg" in ini:
        q0 = quat_from_euler_zxy(r.vector(ini, "euler_zxy_deg", "initial.euler_zxy_deg", 3))
    else:
        q0 = r.vector(ini, "orientation", "initial.orientation", 4, default=[1.0, 0.0, 0.0, 0.0])
        big = float(np.max(np.abs(q0)))
        if not big > 1e-12:  # (w, x, y, z) all ~0: no rotation can be recovered
            raise r.err("initial.orientation", "is zero; must be a non-zero quaternion (w, x, y, z)")
        q0 = q0 / big  # scale first so the norm cannot overflow (components up to 1.8e308 are finite)
        q0 = q0 / float(np.linalg.norm(q0))
    if "angular_velocity" in ini and "angular_velocity_body" in ini:
        raise r.err("initial.angular_velocity",
                    "give exactly one of angular_velocity (world) and angular_velocity_body")
    if "angular_velocity_body" in ini:
        w0 = rotate(q0, r.vector(ini, "angular_velocity_body", "initial.angular_velocity_body", 3))
    else:
        w0 = r.vector(ini, "angular_velocity", "initial.angular_velocity", 3, default=[0.0, 0.0, 0.0])

    return State(x0, v0, q0, w0)


def _parse_forces(r, raw, dt, com_offset) -> ForceModel:
    """The [forces] table; body points are taken from the COM (shifted by ``com_offset``: a particle body's
    COM in the particles' coordinates, or the COM in the body frame of a body given with com or parts)."""
    fr = r.table(raw, "forces", required=False)
    r.check_keys(fr, _FORCES, "forces")
    gravity = r.vector(fr, "gravity", "forces.gravity", 3, default=[0.0, 0.0, 0.0])
    drag = r.number(fr, "linear_drag", "forces.linear_drag", default=0.0, nonneg=True)
    decays = []
    for key in ("velocity_decay", "angular_velocity_decay"):
        g = r.number(fr, key, f"forces.{key}", default=1.0)
        if not 0.0 < g <= 1.0:
            raise r.err(f"forces.{key}", f"must be in (0, 1] (a per-step factor; 1 = off), got {g:g}")
        decays.append(g)

    def body_point(d, key, fld):
        """A body point of the file (attach, point) -> from the COM (m, body axes). For a particle body
        the file gives it in the particles' own coordinates, for a body given with com or parts from the
        body frame's origin: shifted by the COM. Omitted: the COM (0 before the shift)."""
        if key not in d:
            return np.zeros(3)
        p = r.vector(d, key, fld, 3)
        return p if com_offset is None else p - com_offset

    def each(table, keys, build):
        """Every ``[[forces.TABLE]]`` entry, its keys checked, built by ``build(entry, where)``."""
        out = []
        for i, d in enumerate(r.array_of_tables(fr, table, f"forces.{table}")):
            where = f"forces.{table}[{i}]"
            r.check_keys(d, keys, where)
            out.append(build(d, where))
        return tuple(out)

    springs = each("spring", _SPRING, lambda s, where: Spring(
        anchor_W=r.vector(s, "anchor", f"{where}.anchor", 3, required=True),
        attach_B=body_point(s, "attach", f"{where}.attach"),
        stiffness_N_per_m=r.number(s, "stiffness", f"{where}.stiffness", required=True, nonneg=True),
        rest_length_m=r.number(s, "rest_length", f"{where}.rest_length", default=0.0, nonneg=True)))
    points = each("point", _POINT, lambda p, where: PointForce(
        force=r.vector(p, "force", f"{where}.force", 3, required=True),
        point_B=body_point(p, "point", f"{where}.point"),
        frame=r.string(p, "frame", f"{where}.frame", default="world", choices=FRAMES)))
    torques = each("torque", _TORQUE, lambda t, where: Torque(
        torque=r.vector(t, "torque", f"{where}.torque", 3, required=True),
        frame=r.string(t, "frame", f"{where}.frame", default="world", choices=FRAMES)))
    return ForceModel(gravity_W=gravity, linear_drag_N_s_per_m=drag, velocity_decay=decays[0],
                      angular_velocity_decay=decays[1], decay_dt_s=dt, springs=springs,
                      point_forces=points, torques=torques)


def _check_scenario(r, sc) -> None:
    """What needs the whole scenario: its physical numbers within the ranges rbcheck judges; a requested
    closed form exists; the run stays within the limits."""
    from cross_checks.scenario.limits import LimitExceeded, check_physical_ranges, check_scenario_limits
    try:
        check_physical_ranges(sc)
    except LimitExceeded as exc:
        raise r.err(exc.field, exc.reason) from None
    if sc.reference == "analytic":
        from cross_checks.scenario.references import analytic_available
        ok, why = analytic_available(sc)
        if not ok:
            raise r.err("reference", f"'analytic' requested but no closed form covers this scenario: {why}")
    try:
        check_scenario_limits(sc)
    except LimitExceeded as exc:
        raise r.err(exc.field, exc.reason) from None


def _check_long_run(r, raw, sc) -> None:
    """A long run has one Δt and physics that conserves the rotational energy and the angular momentum about
    the COM (no torque, drag, decay or spring; uniform gravity acts at the COM and is allowed): what its
    metrics (cross_checks.analysis.long_run.drift_metrics) measure the drift of."""
    if "dt_ladder" in raw:
        raise r.err("dt_ladder", 'a long run (kind = "long_run") runs at its one dt; remove dt_ladder')
    fm = sc.problem.forces
    for key, present in (("spring", bool(fm.springs)), ("point", bool(fm.point_forces)),
                         ("torque", bool(fm.torques)), ("linear_drag", fm.linear_drag_N_s_per_m != 0.0),
                         ("velocity_decay", fm.velocity_decay != 1.0),
                         ("angular_velocity_decay", fm.angular_velocity_decay != 1.0)):
        if present:
            raise r.err(f"forces.{key}", 'a long run (kind = "long_run") measures the drift of the energy '
                        "and the angular momentum, which this force changes; only gravity may act")


def _check_ladder_spacing(r, vals, ladder):
    """Adjacent rungs closer than MIN_LADDER_RATIO cannot resolve an order (their errors differ by
    noise): refuse them, naming both entries as the user wrote them."""
    for a, b in zip(ladder, ladder[1:]):
        if a / b < MIN_LADDER_RATIO:
            ia, ib = sorted((vals.index(a), vals.index(b)))
            raise r.err(f"dt_ladder[{ib}]",
                        f"{vals[ib]!r} is too close to dt_ladder[{ia}] = {vals[ia]!r} (ratio "
                        f"{max(a, b) / min(a, b):.17g}); adjacent rungs must differ by a factor "
                        f"of at least {MIN_LADDER_RATIO:g} for their errors to give an order")
