"""A student's rigid-body simulator, written from the course equations in plain Python (no NumPy, no
rbcheck code): the zoo ``rbcheck check`` must judge. Each bug flag plants ONE classic mistake.

The step is the course's (semi-implicit Euler, then ``ω += Δt I⁻¹ (τ − ω × I ω)``, ``q += ½Δt [0, ω] q``,
normalise), optionally with the exponential-map rotation (``scheme="expmap"``) or explicit Euler on
the whole state (``scheme="explicit"``). Decay: ``v ← e^{−kΔt} v`` with ``k = −ln γ / dt_scenario``.
Rows are written as a real program would: every step, every ``write_every`` steps, with ``t += dt``
accumulated in single precision (``float32_time``), or the whole state in single precision (``float32``).
"""
from __future__ import annotations

import math
import struct

BUGS = {
    "gyro_sign": "the gyroscopic term has the wrong sign",
    "no_gyro": "no gyroscopic term (the course's own step)",
    "quat_right": "the quaternion update multiplies on the wrong side",
    "omega_body": "ω is taken in the wrong frame",
    "inertia_body": "the inertia is not rotated into world axes",
    "inertia_transposed": "the inertia is rotated the wrong way",
    "torque_order": "the torque is f × r instead of r × f",
    "lever_body": "the lever arm is not rotated",
    "no_point_torque": "produce no torque",
    "torque_world": "applied in world axes",
    "attach_body": "the spring's attachment point is not rotated",
    "no_half": "lacks the ½",
    "no_normalise": "not renormalised",
    "decay_twice": "decay is applied twice",
    "no_decay": "decay is not applied",
    "decay_per_step": "frame-rate dependent",
    "drag_sign": "drag pushes along the velocity",
    "gravity_y": "gravity acts along the wrong axis",
    "dt_mismatch": "Δt mismatch",
}


def f32(x):
    return struct.unpack("f", struct.pack("f", x))[0]


def add(a, b):
    return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]


def scale(s, a):
    return [s * a[0], s * a[1], s * a[2]]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def qmul(p, q):
    """Hamilton product of (w, x, y, z) quaternions."""
    s1, v1, s2, v2 = p[0], p[1:], q[0], q[1:]
    v = add(add(scale(s1, v2), scale(s2, v1)), cross(v1, v2))
    return [s1 * s2 - (v1[0] * v2[0] + v1[1] * v2[1] + v1[2] * v2[2])] + v


def rot(q):
    """Rotation matrix of a unit quaternion (w, x, y, z), rows."""
    w, x, y, z = q
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]


def mv(M, a):
    return [M[i][0] * a[0] + M[i][1] * a[1] + M[i][2] * a[2] for i in range(3)]


def mm(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def tr(A):
    return [[A[j][i] for j in range(3)] for i in range(3)]


def inv3(A):
    a, b, c = A[0]
    d, e, f = A[1]
    g, h, i = A[2]
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return [[(e * i - f * h) / det, (c * h - b * i) / det, (b * f - c * e) / det],
            [(f * g - d * i) / det, (a * i - c * g) / det, (c * d - a * f) / det],
            [(d * h - e * g) / det, (b * g - a * h) / det, (a * e - b * d) / det]]


def qexp(rv):
    th = math.sqrt(rv[0] ** 2 + rv[1] ** 2 + rv[2] ** 2)
    if th < 1e-12:
        return [1.0, 0.5 * rv[0], 0.5 * rv[1], 0.5 * rv[2]]
    s = math.sin(0.5 * th) / th
    return [math.cos(0.5 * th), s * rv[0], s * rv[1], s * rv[2]]


class Student:
    """One body of a scenario (read from a parsed rbcheck Scenario's problem: its numbers only)."""

    def __init__(self, scenario, bug: str = "", scheme: str = "course"):
        p = scenario.problem
        self.m = float(p.body.mass_kg)
        self.I_B = [list(map(float, r)) for r in p.body.inertia_B]
        fm = p.forces
        self.g = [float(c) for c in fm.gravity_W]
        if bug == "gravity_y":
            self.g = [self.g[0], self.g[2], self.g[1]]
        self.c = float(fm.linear_drag_N_s_per_m)
        self.kv = -math.log(fm.velocity_decay) / scenario.dt_s
        self.kw = -math.log(fm.angular_velocity_decay) / scenario.dt_s
        self.gamma = (fm.velocity_decay, fm.angular_velocity_decay)
        self.springs = [([float(c) for c in s.anchor_W], [float(c) for c in s.attach_B],
                         float(s.stiffness_N_per_m), float(s.rest_length_m)) for s in fm.springs]
        self.points = [([float(c) for c in pf.force], [float(c) for c in pf.point_B], pf.frame)
                       for pf in fm.point_forces]
        self.torques = [([float(c) for c in t.torque], t.frame) for t in fm.torques]
        ini = p.initial
        self.state = ([float(c) for c in ini.x_W], [float(c) for c in ini.v_W], [float(c) for c in ini.q_WB],
                      [float(c) for c in ini.w_W])
        self.bug, self.scheme = bug, scheme
        self.dt_scenario = scenario.dt_s

    def force_torque(self, x, v, q):
        R = rot(q)
        f = scale(self.m, self.g)
        tau = [0.0, 0.0, 0.0]
        f = add(f, scale(-self.c if self.bug != "drag_sign" else self.c, v))
        for anchor, attach, k, L0 in self.springs:
            r = mv(R, attach) if self.bug != "attach_body" else attach
            d = [x[i] + r[i] - anchor[i] for i in range(3)]
            L = math.sqrt(sum(c * c for c in d))
            fs = scale(-k * (L - L0) / L, d) if L > 0 else [0.0, 0.0, 0.0]
            f = add(f, fs)
            tau = add(tau, self._torque(R, attach, fs))
        for force, point, frame in self.points:
            body = (frame == "body") != (self.bug == "torque_world")
            fw = mv(R, force) if body else force
            f = add(f, fw)
            if any(point):
                tau = add(tau, self._torque(R, point, fw))
        for t, frame in self.torques:
            body = (frame == "body") != (self.bug == "torque_world")
            tau = add(tau, mv(R, t) if body else t)
        return f, tau

    def _torque(self, R, r_B, f):
        if self.bug == "no_point_torque":
            return [0.0, 0.0, 0.0]
        r = r_B if self.bug == "lever_body" else mv(R, r_B)
        return cross(f, r) if self.bug == "torque_order" else cross(r, f)

    def angular_acceleration(self, q, w, tau):
        R = rot(q)
        if self.bug == "inertia_body":
            I = self.I_B
        elif self.bug == "inertia_transposed":
            I = mm(mm(tr(R), self.I_B), R)
        else:
            I = mm(mm(R, self.I_B), tr(R))
        gyro = [0.0, 0.0, 0.0] if self.bug == "no_gyro" else cross(w, mv(I, w))
        sign = 1.0 if self.bug == "gyro_sign" else -1.0
        return mv(inv3(I), add(tau, scale(sign, gyro)))

    def decay(self, h):
        if self.bug == "no_decay":
            return 1.0, 1.0
        if self.bug == "decay_per_step":
            return self.gamma
        p = 2.0 if self.bug == "decay_twice" else 1.0
        return math.exp(-p * self.kv * h), math.exp(-p * self.kw * h)

    def rotate_quaternion(self, q, w, h):
        if self.scheme == "expmap":
            q1 = qmul(qexp(scale(h, w)), q)
        else:
            half = 1.0 if self.bug == "no_half" else 0.5
            if self.bug == "omega_body":
                w = mv(tr(rot(q)), w)
            om = [0.0] + scale(half * h, w)
            dq = qmul(q, om) if self.bug == "quat_right" else qmul(om, q)
            q1 = [q[i] + dq[i] for i in range(4)]
        if self.bug != "no_normalise":
            n = math.sqrt(sum(c * c for c in q1))
            q1 = [c / n for c in q1]
        return q1

    def step(self, h):
        if self.bug == "dt_mismatch":
            h = 1.1 * h
        x, v, q, w = self.state
        f, tau = self.force_torque(x, v, q)
        gv, gw = self.decay(h)
        alpha = self.angular_acceleration(q, w, tau)
        v1 = scale(gv, add(v, scale(h / self.m, f)))
        w1 = scale(gw, add(w, scale(h, alpha)))
        if self.scheme == "explicit":       # explicit Euler: positions from the old velocities
            x1 = add(x, scale(h, v))
            q1 = self.rotate_quaternion(q, w, h)
        else:                               # the course: positions from the new velocities
            x1 = add(x, scale(h, v1))
            q1 = self.rotate_quaternion(q, w1, h)
        self.state = (x1, v1, q1, w1)


def run(scenario, dt, *, bug="", scheme="course", duration=None,
        write_every=1, float32=False, float32_time=False):
    """Rows (t, x(3), v(3), q(4), ω(3)) of a student run, recorded as the options say."""
    s = Student(scenario, bug, scheme)
    T = scenario.duration_s if duration is None else duration
    n = int(round(T / dt))
    rows = []
    t = 0.0
    for k in range(n + 1):
        if k % write_every == 0:
            x, v, q, w = s.state
            vals = [t] + x + v + q + w
            rows.append([f32(c) for c in vals] if float32 else vals)
        if k < n:
            s.step(dt)
            t = f32(t + f32(dt)) if (float32_time or float32) else (k + 1) * dt
        if float32:
            s.state = tuple([f32(c) for c in part] for part in s.state)
    return rows


def write_csv(path, rows, *, fmt="repr",
              columns=("t", "x", "y", "z", "vx", "vy", "vz", "qw", "qx", "qy", "qz", "wx", "wy", "wz")):
    """Write rows with a header; ``fmt``: "repr" (round-trip), "%.6f", "%.9g" (a float32 printed in full)."""
    order = ["t", "x", "y", "z", "vx", "vy", "vz", "qw", "qx", "qy", "qz", "wx", "wy", "wz"]
    idx = [order.index(c) for c in columns]
    out = [",".join(columns)]
    for r in rows:
        out.append(",".join(repr(r[i]) if fmt == "repr" else (fmt % r[i]) for i in idx))
    with open(path, "w") as fh:
        fh.write("\n".join(out) + "\n")
    return path
