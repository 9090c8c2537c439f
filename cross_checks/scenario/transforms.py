"""Scenario transforms with an exact, known effect on the motion: the invariance checks (docs/invariance.md).

Each transform writes the same physics another way. Run by a correct simulator, the transformed scenario
moves exactly as the original does, once its states are mapped back to the original's frame
(:meth:`Transform.map_back`); what is left is the simulator's round-off (judged by
:func:`cross_checks.analysis.judge.judge_invariance`).

* :class:`Translation` of the world origin by ``d_W_m``: the COM and every spring anchor shift by d;
  nothing else changes. Mapped back: ``x = x' − d``.
* :class:`WorldRotation` of the world frame by the unit quaternion ``r`` (R = R(r)): gravity, the initial
  state (x, v, q, ω), world-frame forces and torques and the spring anchors are rotated; body-frame
  quantities are unchanged. Mapped back: ``x = Rᵀx'``, ``v = Rᵀv'``, ``q = r⁻¹ q'``, ``ω = Rᵀω'``.
* :class:`BodyFrame`: the body described in a body frame B' turned by ``p`` from the original B
  (``r_B = P r_B'``, P = R(p)): the inertia becomes the full tensor ``Pᵀ I P`` (not principal), the
  orientation ``q' = q p``, body points and body-frame forces and torques ``Pᵀ·``; world ω is unchanged.
  Mapped back: ``q = q' p⁻¹``.
* :class:`Scale`: lengths × k and masses × μ with time unchanged, under which Newton's and Euler's
  equations are exactly covariant: positions, velocities, gravity, anchors, attach points, rest lengths
  × k; ω, the decay factors and the orientation unchanged; forces × μk, torques and inertia × μk²,
  stiffness and drag × μ. Mapped back: ``x = x'/k``, ``v = v'/k``.
* :class:`ComOffset`: the body's own frame origin moved off its COM (``body.com`` = c, ``radii`` radii of
  gyration along a generic axis): the initial position and velocity become the origin's (``x − R c``,
  ``v − ω × R c``) and body points are given from the origin (``+ c``). Engines still report the COM's state:
  mapped back, nothing changes.
* :class:`WeldedSplit`: the body given as two welded parts (``[[body.parts]]``) whose total mass, COM and
  inertia are the original's (MuJoCo #3553's class: a free body with a massive fixed child): the child
  takes ``child_mass`` of the mass and ``child_inertia`` of what the parallel-axis terms leave, the parts'
  COMs ``separation`` radii of gyration apart on either side of the COM. Mapped back: nothing changes.

:func:`apply` returns a validated :class:`~cross_checks.scenario.Scenario` (the transformed file is parsed
like any scenario file, so engine files receive it as their resolved JSON), or raises
:class:`TransformRefused` naming the field that would leave the physical ranges rbcheck judges
(docs/hardening.md; :mod:`cross_checks.scenario.limits`).
"""
from __future__ import annotations

import abc
import json
import math
from dataclasses import dataclass

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.scenario.parse import ScenarioError, parse_scenario
from reference_sim.quaternion import matrix_from_quat, quat_conj, quat_from_axis_angle, quat_mul
from reference_sim.state import Q, V, W, X

__all__ = ["Transform", "Translation", "WorldRotation", "BodyFrame", "Scale", "ComOffset", "WeldedSplit",
           "TransformRefused",
           "TRANSFORM_KINDS", "TRANSFORM_PARAMETERS", "default_transforms", "apply", "scenario_dict",
           "toml_text"]

#: The kinds of transform, in the order the sweep runs and reports them.
TRANSFORM_KINDS = ("translation", "rotation", "body_frame", "scale", "com_offset", "welded_split")

#: The named sizes of each kind (``Transform.parameters``), which a declared invariance finding bounds
#: (engines.base.InvarianceFinding): translation ``distance_m`` |d| (m); rotation and body_frame
#: ``angle_deg``; scale ``k`` (lengths) and ``mu`` (masses); com_offset ``gyration_radii``; welded_split
#: ``child_mass``.
TRANSFORM_PARAMETERS = {"translation": ("distance_m",), "rotation": ("angle_deg",),
                        "body_frame": ("angle_deg",), "scale": ("k", "mu"), "com_offset": ("gyration_radii",),
                        "welded_split": ("child_mass",)}

#: Directions and axes of the default transforms: integer vectors of exact length 7 (2² + 3² + 6² = 7²),
#: so each is exact in binary after dividing by 7 only up to one rounding, and none lies along a coordinate
#: axis (gravity turns to a direction with three non-zero components; the inertia gets every off-diagonal
#: entry).
_DIRECTION = np.array([2.0, -3.0, 6.0]) / 7.0
_ROTATION_AXIS = np.array([6.0, 2.0, -3.0]) / 7.0
_BODY_AXIS = np.array([-3.0, 6.0, 2.0]) / 7.0
_COM_AXIS = np.array([6.0, -2.0, 3.0]) / 7.0
_SPLIT_AXIS = np.array([3.0, 2.0, -6.0]) / 7.0


class TransformRefused(ValueError):
    """A transform that would take the scenario outside what rbcheck judges (or a transform given out of
    its own range): ``field`` (of the transformed scenario, or of the transform) and ``reason``."""

    def __init__(self, transform: str, field_: str, reason: str):
        self.transform, self.field, self.reason = transform, field_, reason
        super().__init__(f"{transform}: {field_}: {reason}")


@dataclass(frozen=True)
class Transform(abc.ABC):
    """A transform: ``kind`` (one of TRANSFORM_KINDS) and ``magnitude`` (its size as one text: "1e+04 m",
    "73 deg", "k=0.01 mu=0.01")."""

    @property
    @abc.abstractmethod
    def kind(self) -> str:
        """One of TRANSFORM_KINDS."""

    @property
    @abc.abstractmethod
    def magnitude(self) -> str:
        """The transform's size as one text."""

    @property
    def label(self) -> str:
        return f"{self.kind} {self.magnitude}"

    @property
    def parameters(self) -> dict:
        """The transform's sizes by name (TRANSFORM_PARAMETERS of its kind): what a declared invariance
        finding's range is checked against."""
        return {}

    @abc.abstractmethod
    def rewrite(self, d: dict) -> dict:
        """The transformed scenario dict (:func:`scenario_dict`'s keys) of ``d``."""

    @abc.abstractmethod
    def map_back(self, y) -> np.ndarray:
        """States ``y (..., 13)`` of the transformed run ([x_W m, v_W m/s, q_WB (w, x, y, z), ω_W rad/s]
        in the transformed world and body frames) in the original's frames."""

    def position_offset_m(self) -> float:
        """How far the transform moves the world origin (m): what a translation adds to the positions'
        magnitude (and so to their round-off); 0 for the others."""
        return 0.0


def _rot(q) -> np.ndarray:
    return matrix_from_quat(np.asarray(q, dtype=float))


@dataclass(frozen=True)
class Translation(Transform):
    """The world origin moved so that every world point is at ``x + d_W_m`` (m)."""

    d_W_m: tuple

    @property
    def kind(self) -> str:
        return "translation"

    @property
    def magnitude(self) -> str:
        return f"{float(np.linalg.norm(self.d_W_m)):.3g} m"

    def position_offset_m(self) -> float:
        return float(np.linalg.norm(self.d_W_m))

    @property
    def parameters(self) -> dict:
        return {"distance_m": float(np.linalg.norm(self.d_W_m))}

    def rewrite(self, d: dict) -> dict:
        dv = np.asarray(self.d_W_m, dtype=float)
        d["initial"]["position"] = list(np.asarray(d["initial"]["position"]) + dv)
        for s in d["forces"]["spring"]:
            s["anchor"] = list(np.asarray(s["anchor"]) + dv)
        return d

    def map_back(self, y) -> np.ndarray:
        y = np.array(y, dtype=float)
        y[..., X] -= np.asarray(self.d_W_m, dtype=float)
        return y


@dataclass(frozen=True)
class WorldRotation(Transform):
    """The world frame turned: every world vector ``u`` becomes ``R u`` (R = R(``r_wxyz``), about the
    origin)."""

    r_wxyz: tuple

    @property
    def kind(self) -> str:
        return "rotation"

    @property
    def magnitude(self) -> str:
        return f"{self.parameters['angle_deg']:.3g} deg"

    @property
    def parameters(self) -> dict:
        return {"angle_deg": math.degrees(2.0 * math.acos(min(1.0, abs(float(self.r_wxyz[0])))))}

    def rewrite(self, d: dict) -> dict:
        R = _rot(self.r_wxyz)
        ini, fr = d["initial"], d["forces"]
        for key in ("position", "velocity", "angular_velocity"):
            ini[key] = list(R @ np.asarray(ini[key]))
        ini["orientation"] = list(quat_mul(np.asarray(self.r_wxyz), np.asarray(ini["orientation"])))
        fr["gravity"] = list(R @ np.asarray(fr["gravity"]))
        for s in fr["spring"]:
            s["anchor"] = list(R @ np.asarray(s["anchor"]))
        for p in fr["point"]:
            if p["frame"] == "world":
                p["force"] = list(R @ np.asarray(p["force"]))
        for t in fr["torque"]:
            if t["frame"] == "world":
                t["torque"] = list(R @ np.asarray(t["torque"]))
        return d

    def map_back(self, y) -> np.ndarray:
        y = np.array(y, dtype=float)
        Rt = _rot(self.r_wxyz).T
        for block in (X, V, W):
            y[..., block] = y[..., block] @ Rt.T
        y[..., Q] = quat_mul(quat_conj(np.asarray(self.r_wxyz, dtype=float)), y[..., Q])
        return y


@dataclass(frozen=True)
class BodyFrame(Transform):
    """The body described in a frame B' turned by ``p_wxyz`` from its principal frame B: ``r_B = P r_B'``
    (P = R(p)); the inertia in B' is the full tensor ``Pᵀ I_B P``."""

    p_wxyz: tuple

    @property
    def kind(self) -> str:
        return "body_frame"

    @property
    def magnitude(self) -> str:
        return f"{self.parameters['angle_deg']:.3g} deg"

    @property
    def parameters(self) -> dict:
        return {"angle_deg": math.degrees(2.0 * math.acos(min(1.0, abs(float(self.p_wxyz[0])))))}

    def rewrite(self, d: dict) -> dict:
        P = _rot(self.p_wxyz)
        b, ini, fr = d["body"], d["initial"], d["forces"]
        inertia = P.T @ np.asarray(b["inertia"]) @ P
        b["inertia"] = [list(row) for row in 0.5 * (inertia + inertia.T)]
        ini["orientation"] = list(quat_mul(np.asarray(ini["orientation"]), np.asarray(self.p_wxyz)))
        for s in fr["spring"]:
            s["attach"] = list(P.T @ np.asarray(s["attach"]))
        for p in fr["point"]:
            p["point"] = list(P.T @ np.asarray(p["point"]))
            if p["frame"] == "body":
                p["force"] = list(P.T @ np.asarray(p["force"]))
        for t in fr["torque"]:
            if t["frame"] == "body":
                t["torque"] = list(P.T @ np.asarray(t["torque"]))
        return d

    def map_back(self, y) -> np.ndarray:
        y = np.array(y, dtype=float)
        y[..., Q] = quat_mul(y[..., Q], quat_conj(np.asarray(self.p_wxyz, dtype=float)))
        return y


@dataclass(frozen=True)
class Scale(Transform):
    """Lengths × ``k`` and masses × ``mu``, time unchanged (both in tolerances.INVARIANCE_SCALE_RANGE)."""

    k: float
    mu: float

    def __post_init__(self):
        lo, hi = tol.INVARIANCE_SCALE_RANGE
        for name, v in (("k", self.k), ("mu", self.mu)):
            if not (isinstance(v, int | float) and math.isfinite(v) and lo <= v <= hi):
                raise TransformRefused("scale", name, f"must be a number in [{lo:g}, {hi:g}] (the range of "
                                                      f"scales rbcheck checks), got {v!r}")

    @property
    def kind(self) -> str:
        return "scale"

    @property
    def magnitude(self) -> str:
        return f"k={self.k:g} mu={self.mu:g}"

    @property
    def parameters(self) -> dict:
        return {"k": float(self.k), "mu": float(self.mu)}

    def rewrite(self, d: dict) -> dict:
        k, mu = float(self.k), float(self.mu)
        b, ini, fr = d["body"], d["initial"], d["forces"]
        b["mass"] = b["mass"] * mu
        b["inertia"] = [[v * mu * k * k for v in row] for row in b["inertia"]]
        for key in ("position", "velocity"):
            ini[key] = [v * k for v in ini[key]]
        fr["gravity"] = [v * k for v in fr["gravity"]]
        fr["linear_drag"] = fr["linear_drag"] * mu
        for s in fr["spring"]:
            s["anchor"] = [v * k for v in s["anchor"]]
            s["attach"] = [v * k for v in s["attach"]]
            s["stiffness"] = s["stiffness"] * mu
            s["rest_length"] = s["rest_length"] * k
        for p in fr["point"]:
            p["force"] = [v * mu * k for v in p["force"]]
            p["point"] = [v * k for v in p["point"]]
        for t in fr["torque"]:
            t["torque"] = [v * mu * k * k for v in t["torque"]]
        return d

    def map_back(self, y) -> np.ndarray:
        y = np.array(y, dtype=float)
        y[..., X] /= float(self.k)
        y[..., V] /= float(self.k)
        return y


def _gyration_radius_m(body: dict) -> float:
    """sqrt(I_max / m) of a scenario dict's body (m): the body's size, by its mass distribution."""
    return math.sqrt(float(np.linalg.eigvalsh(np.asarray(body["inertia"], dtype=float))[-1]) / body["mass"])


@dataclass(frozen=True)
class ComOffset(Transform):
    """The body frame's origin moved off the COM: the COM at ``radii`` radii of gyration (sqrt(I_max/m))
    along a generic body axis from the origin (``body.com``)."""

    radii: float = tol.INVARIANCE_COM_OFFSET_GYRATION_RADII

    @property
    def kind(self) -> str:
        return "com_offset"

    @property
    def magnitude(self) -> str:
        return f"{self.radii:g} gyration radii"

    @property
    def parameters(self) -> dict:
        return {"gyration_radii": float(self.radii)}

    def com_B_m(self, d: dict) -> np.ndarray:
        """The COM in the body frame (m, body axes, from the origin) this transform gives ``d``'s body."""
        return self.radii * _gyration_radius_m(d["body"]) * _COM_AXIS

    def rewrite(self, d: dict) -> dict:
        c = self.com_B_m(d)
        b, ini, fr = d["body"], d["initial"], d["forces"]
        r_W = _rot(ini["orientation"]) @ c
        b["com"] = list(c)
        ini["position"] = list(np.asarray(ini["position"]) - r_W)
        w_W = np.asarray(ini["angular_velocity"])
        ini["velocity"] = list(np.asarray(ini["velocity"]) - np.cross(w_W, r_W))
        for s in fr["spring"]:
            s["attach"] = list(np.asarray(s["attach"]) + c)
        for p in fr["point"]:
            p["point"] = list(np.asarray(p["point"]) + c)
        return d

    def map_back(self, y) -> np.ndarray:
        return np.array(y, dtype=float)


@dataclass(frozen=True)
class WeldedSplit(Transform):
    """The body as two welded parts with its total mass, COM and inertia: a parent and a child taking
    ``child_mass`` of the mass, their COMs ``separation`` radii of gyration apart along a generic axis (on
    either side of the COM, so it stays at the origin), the inertia the parallel-axis terms leave shared
    ``1 − child_inertia`` : ``child_inertia``. The parts lie apart perpendicular to the axis of the largest
    moment (in a flat body's plane); the separation is halved until both parts' inertias are physical."""

    child_mass: float = tol.INVARIANCE_SPLIT_CHILD_MASS_FRACTION
    child_inertia: float = tol.INVARIANCE_SPLIT_CHILD_INERTIA_FRACTION
    separation: float = tol.INVARIANCE_SPLIT_SEPARATION_GYRATION_RADII

    @property
    def kind(self) -> str:
        return "welded_split"

    @property
    def magnitude(self) -> str:
        return f"child {self.child_mass:g} of the mass"

    @property
    def parameters(self) -> dict:
        return {"child_mass": float(self.child_mass)}

    def parts(self, d: dict) -> list:
        """The two parts ``[parent, child]`` of the body of ``d``: dicts of mass (kg), com (m, body axes from
        the COM) and inertia (3×3 kg m² about the part's COM)."""
        from reference_sim.body import check_inertia
        m, inertia = float(d["body"]["mass"]), np.asarray(d["body"]["inertia"], dtype=float)
        f = float(self.child_mass)
        # the parts apart along a generic direction perpendicular to the axis of the largest moment: in a flat
        # body's plane (A + B = C: every part of a flat body is flat in that plane, or it is not physical)
        axis = np.linalg.eigh(inertia)[1][:, -1]
        u = _SPLIT_AXIS - float(_SPLIT_AXIS @ axis) * axis
        u = u / float(np.linalg.norm(u))
        s = self.separation * _gyration_radius_m(d["body"])
        lam_min = float(np.linalg.eigvalsh(inertia)[0])
        for _ in range(60):
            J = m * f * (1.0 - f) * s * s * (np.eye(3) - np.outer(u, u))
            rest = inertia - J
            try:
                check_inertia(rest)
                if float(np.linalg.eigvalsh(rest)[0]) >= 0.25 * lam_min:
                    break
            except ValueError:
                pass
            s *= 0.5
        a = float(self.child_inertia)
        return [{"mass": m * (1.0 - f), "com": list(f * s * u),
                 "inertia": [list(r) for r in (1.0 - a) * rest]},
                {"mass": m * f, "com": list(-(1.0 - f) * s * u), "inertia": [list(r) for r in a * rest]}]

    def rewrite(self, d: dict) -> dict:
        parts = self.parts(d)
        b = d["body"]
        del b["mass"], b["inertia"]
        b["parts"] = parts
        return d

    def map_back(self, y) -> np.ndarray:
        return np.array(y, dtype=float)


def default_transforms() -> list:
    """The transforms ``rbcheck sweep --invariance`` runs on every (variant, scenario): translations by
    tolerances.INVARIANCE_TRANSLATIONS_M, one rotation of the world frame and one of the body frame by
    generic angles about generic axes, the scales tolerances.INVARIANCE_SCALES, the body frame's origin off
    its COM and the body split into two welded parts."""
    out: list = [Translation(tuple(m * _DIRECTION)) for m in tol.INVARIANCE_TRANSLATIONS_M]
    out.append(WorldRotation(tuple(quat_from_axis_angle(_ROTATION_AXIS, math.radians(135.0)))))
    out.append(BodyFrame(tuple(quat_from_axis_angle(_BODY_AXIS, math.radians(41.0)))))
    out += [Scale(k, mu) for k, mu in tol.INVARIANCE_SCALES]
    out += [ComOffset(), WeldedSplit()]
    return out


# --- the scenario as a dict, and back --------------------------------------------------------------------

def _vec(a) -> list:
    return [float(v) for v in np.asarray(a, dtype=float).ravel()]


def scenario_dict(scenario) -> dict:
    """The scenario's physics in the scenario file's keys, every alternative resolved: mass and the 3×3
    inertia about the COM, the COM's position, orientation (w, x, y, z) and WORLD ω, body points from the
    COM (a particle body's COM offset applied), the decay factors at the scenario's dt."""
    p = scenario.problem
    y0 = p.initial_packed()
    fm = p.forces
    d = {"name": scenario.name, "description": scenario.description, "kind": scenario.kind,
         "duration": float(scenario.duration_s), "dt": float(scenario.dt_s),
         "reference": "auto" if scenario.reference == "analytic" else scenario.reference,
         "body": {"mass": float(p.body.mass_kg), "inertia": [_vec(r) for r in p.body.inertia_B]},
         "initial": {"position": _vec(y0[X]), "velocity": _vec(y0[V]), "orientation": _vec(y0[Q]),
                     "angular_velocity": _vec(y0[W])},
         "forces": {"gravity": _vec(fm.gravity_W), "linear_drag": float(fm.linear_drag_N_s_per_m),
                    "velocity_decay": float(fm.velocity_decay),
                    "angular_velocity_decay": float(fm.angular_velocity_decay),
                    "spring": [{"anchor": _vec(s.anchor_W), "attach": _vec(s.attach_B),
                                "stiffness": float(s.stiffness_N_per_m),
                                "rest_length": float(s.rest_length_m)}
                               for s in fm.springs],
                    "point": [{"force": _vec(f.force), "point": _vec(f.point_B), "frame": f.frame}
                              for f in fm.point_forces],
                    "torque": [{"torque": _vec(t.torque), "frame": t.frame} for t in fm.torques]}}
    if "dt_ladder" in scenario.raw:
        d["dt_ladder"] = [float(v) for v in scenario.dt_ladder_s]
    return d


def _toml_value(v) -> str:
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(e) for e in v) + "]"
    f = float(v)
    if not math.isfinite(f):
        raise ValueError(f"not a finite number: {f!r}")
    return repr(f)


def toml_text(d: dict) -> str:
    """:func:`scenario_dict`'s dict as a scenario file (TOML): floats printed to round-trip exactly."""
    lines = [f"{k} = {_toml_value(d[k])}" for k in ("name", "description", "kind", "duration", "dt",
                                                      "dt_ladder", "reference") if k in d]
    for table in ("body", "initial"):
        lines += ["", f"[{table}]"] + [f"{k} = {_toml_value(v)}" for k, v in d[table].items() if k != "parts"]
    for part in d["body"].get("parts", ()):
        lines += ["", "[[body.parts]]"] + [f"{k} = {_toml_value(v)}" for k, v in part.items()]
    fr = d["forces"]
    lines += ["", "[forces]"] + [f"{k} = {_toml_value(v)}" for k, v in fr.items()
                                 if not isinstance(v, list) or k == "gravity"]
    for arr in ("spring", "point", "torque"):
        for entry in fr[arr]:
            lines += ["", f"[[forces.{arr}]]"] + [f"{k} = {_toml_value(v)}" for k, v in entry.items()]
    return "\n".join(lines) + "\n"


def apply(transform: Transform, scenario):
    """The scenario ``transform`` makes of ``scenario``: validated as any scenario file (same name, its
    description saying the transform). Raises TransformRefused naming the field (of the transformed
    scenario) that would leave what rbcheck judges."""
    d = transform.rewrite(scenario_dict(scenario))
    d["description"] = (f"{scenario.description} [invariance: {transform.label}]").strip()
    try:
        return parse_scenario(toml_text(d), f"{scenario.source} [{transform.label}]")
    except ScenarioError as exc:
        raise TransformRefused(f"{transform.label} of {scenario.name}", exc.field, exc.reason) from None
