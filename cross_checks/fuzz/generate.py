"""Random scenarios over the whole schema, with the dimensionless numbers that decide fairness under control.

A case is drawn in two parts:

* :func:`draw` — everything about the physics, in the units of a base rate Ω (rad/s), a mass and a size:
  the body, the initial state and every force kind of the schema, each present at random (docs/fuzz.md §1).
* :meth:`CaseDraw.spec` — the scenario file at a coarsest step h (dt = h, ladder [h, h/2, h/4], duration
  n0·h). The step is what makes a case fair: :func:`cross_checks.fuzz.pipeline.prepare` picks h from the
  measured numbers h·L, χ = ½ L² h T (drawn log-uniformly up to FUZZ_CHI_MAX) and A·χ, never from the draw
  alone (bounds and their derivations: ``cross_checks/core/tolerances.py``, "rbcheck fuzz"; docs/fuzz.md §1).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from cross_checks.core import tolerances as tol
from reference_sim.quaternion import matrix_from_quat, quat_normalize

__all__ = ["CaseDraw", "draw", "to_toml", "case_rng", "SHAPES", "SPIN_KINDS"]

SHAPES = ("generic", "symmetric", "near_symmetric", "isotropic", "flat")
SPIN_KINDS = ("tumble", "principal", "separatrix", "rest")


def case_rng(seed: int, index: int) -> np.random.Generator:
    """The generator of case ``index`` of campaign ``seed``: independent of every other case, so a case
    is the same whichever worker draws it and whatever was drawn before."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(index)]))


def _loguniform(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _random_quat(rng):
    return quat_normalize(rng.normal(size=4))


@dataclass
class CaseDraw:
    """The random part of a case (see the module docstring). Lengths m, masses kg, rates rad/s or 1/s.

    body : the ``[body]`` table (mass + inertia, or particles); ``com_B`` where the particles' COM is in
        their own coordinates (body points are written in those coordinates); ``moments`` principal
        moments (kg m², ascending), ``R_BP`` the principal axes in body coordinates.
    initial : the ``[initial]`` table. forces : the ``[forces]`` table WITHOUT the decay factors, which
        depend on the step: ``decay_rates`` (k_v, k_ω) in 1/s (γ = e^(−k h) at dt = h).
    chi : the drawn amplitude drift χ at the coarsest step. omega : the base rate Ω (rad/s) the draw was
        made in; a motion with no rate of its own (a projectile) is timed by it. kinds : what was drawn.
    """

    seed: int
    index: int
    body: dict
    com_B: np.ndarray
    moments: np.ndarray
    R_BP: np.ndarray
    initial: dict
    forces: dict
    decay_rates: tuple
    chi: float
    omega: float = 1.0
    kinds: dict = field(default_factory=dict)

    @property
    def name(self) -> str:
        return f"fuzz_{self.seed}_{self.index}"

    def spec(self, h_s: float, n0: int, description: str = "") -> dict:
        """The scenario file (a dict in the TOML schema) at coarsest step ``h_s``, ``n0`` steps long."""
        forces = {k: v for k, v in self.forces.items()}
        kv, kw = self.decay_rates
        if kv:
            forces["velocity_decay"] = math.exp(-kv * h_s)
        if kw:
            forces["angular_velocity_decay"] = math.exp(-kw * h_s)
        return {"name": self.name,
                "description": description or f"rbcheck fuzz case {self.index} of seed {self.seed}",
                "duration": n0 * h_s, "dt": h_s, "dt_ladder": [h_s, h_s / 2.0, h_s / 4.0],
                "body": dict(self.body), "initial": dict(self.initial), "forces": forces}


# --- the body -----------------------------------------------------------------------------------------

def _moments(rng, shape, mass, size):
    """Principal moments (kg m², unsorted: any axis may be the intermediate one) of a ``shape``."""
    r2 = mass * size * size
    if shape == "isotropic":
        return np.full(3, 0.4 * r2)
    if shape in ("symmetric", "near_symmetric"):
        a, c = 0.4 * r2, 0.4 * r2 * rng.uniform(0.2, 2.0)
        eps = 10.0 ** rng.uniform(-6, -2) if shape == "near_symmetric" else 0.0
        m = np.array([a, a * (1.0 + eps), c])
    elif shape == "flat":  # nearly a lamina: I1 + I2 = I3 (1 + margin), margin ≥ FUZZ_TRIANGLE_MARGIN
        a, b = size * rng.uniform(0.2, 1.0), size * rng.uniform(0.2, 1.0)
        i1, i2 = mass * b * b / 12.0, mass * a * a / 12.0
        margin = 10.0 ** rng.uniform(math.log10(tol.FUZZ_TRIANGLE_MARGIN), -2.0)
        m = np.array([i1, i2, (i1 + i2) / (1.0 + margin)])
    else:  # a box of random proportions (up to 10:1): anisotropic, never violating A + B >= C
        a, b, c = size * np.exp(rng.uniform(math.log(0.1), 0.0, size=3))
        m = mass / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    return m[rng.permutation(3)]


def _particles(rng, mass, size):
    """4–7 point masses around an offset origin (their COM need not be at 0): [[m, x, y, z], ...]."""
    from reference_sim.body import RigidBody
    while True:
        k = int(rng.integers(4, 8))   # three points are always coplanar: a lamina (see _margin_ok)
        w = np.exp(rng.uniform(-1.0, 1.0, size=k))
        masses = mass * w / w.sum()
        offset = size * rng.normal(size=3) * 2.0
        pts = offset + size * rng.normal(size=(k, 3))
        P = np.column_stack([masses, pts])
        try:
            body, com = RigidBody.from_particles(P)
        except ValueError:
            continue
        ev = np.linalg.eigvalsh(body.inertia_B)
        if (ev[0] >= tol.FUZZ_MIN_INERTIA_RATIO * ev[-1]
                and ev[0] + ev[1] >= ev[2] * (1.0 + tol.FUZZ_TRIANGLE_MARGIN)):
            return P, body, com


def _draw_body(rng, kinds):
    mass = _loguniform(rng, 0.05, 20.0)
    size = _loguniform(rng, 0.05, 2.0)
    kind = rng.choice(["moments", "tensor", "particles"], p=[0.4, 0.35, 0.25])
    kinds["body"] = str(kind)
    if kind == "particles":
        P, body, com = _particles(rng, mass, size)
        moments, R = body.principal_axes()
        kinds["shape"] = "particles"
        return {"particles": P.tolist()}, com, moments, R, size, body.mass_kg
    shape = str(rng.choice(SHAPES, p=[0.5, 0.15, 0.15, 0.05, 0.15]))
    kinds["shape"] = shape
    m = _moments(rng, shape, mass, size)
    if kind == "moments":
        R, inertia = np.eye(3), m.tolist()
    else:
        R = matrix_from_quat(_random_quat(rng))   # principal axes in body coordinates: products of inertia
        I = R @ np.diag(m) @ R.T
        inertia = (0.5 * (I + I.T)).tolist()
    order = np.argsort(m)
    R = R[:, order]
    if np.linalg.det(R) < 0:
        R[:, 2] *= -1.0
    return {"mass": mass, "inertia": inertia}, np.zeros(3), m[order], R, size, mass


# --- the initial state ------------------------------------------------------------------------------

def _spin_principal(rng, kind, moments, omega):
    """ω in principal axes (rad/s) for a spin ``kind`` (see SPIN_KINDS)."""
    if kind == "rest":
        return np.zeros(3)
    if kind == "tumble":
        return omega * _unit(rng)
    axis = 1 if kind == "separatrix" else int(rng.integers(0, 3))
    w = np.zeros(3)
    w[axis] = omega * (1.0 if rng.random() < 0.5 else -1.0)
    if rng.random() < 0.9:  # a small wobble off the axis (kept exactly on it one time in ten)
        w += omega * 10.0 ** rng.uniform(-4, -1) * _unit(rng)
    return w


def _draw_initial(rng, kinds, moments, R_BP, omega, size):
    ini = {}
    if rng.random() < 0.7:
        ini["position"] = (size * 3.0 * rng.normal(size=3)).tolist()
    if rng.random() < 0.7:
        ini["velocity"] = (omega * size * rng.uniform(0.0, 3.0) * _unit(rng)).tolist()
    distinct = min(np.diff(moments)) > 1e-3 * moments[-1]
    spin = str(rng.choice(SPIN_KINDS, p=[0.4, 0.25, 0.25, 0.1]))
    if spin == "separatrix" and not distinct:
        spin = "tumble"
    kinds["spin"] = spin
    w_B = R_BP @ _spin_principal(rng, spin, moments, omega * rng.uniform(0.3, 1.0))
    u = rng.random()
    if u < 0.15:
        angles = rng.uniform(-180.0, 180.0, size=3)
        angles[1] = rng.uniform(-80.0, 80.0)  # pitch away from gimbal lock
        ini["euler_zxy_deg"] = angles.tolist()
        from reference_sim.quaternion import quat_from_euler_zxy
        q = quat_from_euler_zxy(angles)
    elif u < 0.3:
        q = np.array([1.0, 0.0, 0.0, 0.0])
    else:
        q = _random_quat(rng)
        ini["orientation"] = q.tolist()
    if rng.random() < 0.5:
        ini["angular_velocity_body"] = w_B.tolist()
    else:
        ini["angular_velocity"] = (matrix_from_quat(q) @ w_B).tolist()
    return ini


# --- the forces ----------------------------------------------------------------------------------------

def _count(rng, p_one, p_two):
    u = rng.random()
    return 2 if u < p_two else (1 if u < p_one + p_two else 0)


def _body_point(rng, size, com_B):
    """A body point in the file's coordinates: off the COM (7 times in 10) by up to 1.5 sizes."""
    r = size * rng.uniform(0.2, 1.5) * _unit(rng) if rng.random() < 0.7 else np.zeros(3)
    return (r + com_B).tolist()


def _draw_forces(rng, kinds, mass, size, moments, com_B, x0, omega):
    f = {}
    present = []
    if rng.random() < 0.6:
        g = rng.uniform(0.5, 20.0) * (np.array([0.0, 0.0, -1.0]) if rng.random() < 0.5 else _unit(rng))
        f["gravity"] = g.tolist()
        present.append("gravity")
    if rng.random() < 0.2:
        f["linear_drag"] = mass * omega * 10.0 ** rng.uniform(-2, 0)
        present.append("drag")
    decay = [0.0, 0.0]
    for i, name in enumerate(("velocity_decay", "angular_velocity_decay")):
        if rng.random() < 0.15:
            decay[i] = omega * 10.0 ** rng.uniform(-2, 0)
            present.append(name)
    springs = []
    for _ in range(_count(rng, 0.3, 0.1)):
        ws = omega * rng.uniform(0.2, 1.0)
        sp = {"anchor": (np.asarray(x0) + 3.0 * size * rng.normal(size=3)).tolist(),
              "attach": _body_point(rng, size, com_B), "stiffness": mass * ws * ws}
        if rng.random() < 0.5:
            sp["rest_length"] = float(rng.uniform(0.0, 2.0) * size)
        springs.append(sp)
    if springs:
        f["spring"] = springs
        present.append("spring")
    points = []
    for _ in range(_count(rng, 0.25, 0.1)):
        points.append({"force": (mass * omega * omega * size * rng.uniform(0.05, 0.5) * _unit(rng)).tolist(),
                       "point": _body_point(rng, size, com_B), "frame": str(rng.choice(["world", "body"]))})
    if points:
        f["point"] = points
        present.append("point")
    torques = []
    for _ in range(_count(rng, 0.25, 0.1)):
        torques.append({"torque": (moments[1] * omega * omega * rng.uniform(0.02, 0.3) * _unit(rng)).tolist(),
                        "frame": str(rng.choice(["world", "body"]))})
    if torques:
        f["torque"] = torques
        present.append("torque")
    kinds["forces"] = present
    return f, tuple(decay)


def draw(seed: int, index: int) -> CaseDraw:
    """Case ``index`` of campaign ``seed`` (deterministic: see :func:`case_rng`)."""
    rng = case_rng(seed, index)
    kinds: dict = {}
    omega = _loguniform(rng, 0.3, 30.0)
    body, com_B, moments, R_BP, size, mass = _draw_body(rng, kinds)
    initial = _draw_initial(rng, kinds, moments, R_BP, omega, size)
    x0 = initial.get("position", [0.0, 0.0, 0.0])
    forces, decay = _draw_forces(rng, kinds, mass, size, moments, com_B, x0, omega)
    chi = _loguniform(rng, tol.FUZZ_CHI_MIN, tol.FUZZ_CHI_MAX)
    return CaseDraw(seed, index, body, np.asarray(com_B, dtype=float), np.asarray(moments), np.asarray(R_BP),
                    initial, forces, decay, chi, omega, kinds)


# --- TOML ------------------------------------------------------------------------------------------------

def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if not math.isfinite(v):
            raise ValueError(f"cannot write the non-finite number {v!r} into a scenario file")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_value(e) for e in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} into a scenario file")


def to_toml(spec: dict, header: str = "") -> str:
    """A scenario dict (the TOML schema of docs/scenario.md) as TOML text, every number exact (repr)."""
    out = [f"# {line}".rstrip() for line in header.splitlines()]
    for key in ("name", "description", "duration", "dt", "dt_ladder", "reference"):
        if key in spec:
            out.append(f"{key} = {_value(spec[key])}")
    for table in ("body", "initial", "forces"):
        t = spec.get(table)
        if t is None:
            continue
        out.append("")
        out.append(f"[{table}]")
        arrays = []
        for k, v in t.items():
            if isinstance(v, list) and v and isinstance(v[0], dict):
                arrays.append((k, v))
            else:
                out.append(f"{k} = {_value(v)}")
        for k, entries in arrays:
            for e in entries:
                out.append("")
                out.append(f"[[{table}.{k}]]")
                out.extend(f"{kk} = {_value(vv)}" for kk, vv in e.items())
    return "\n".join(out) + "\n"
