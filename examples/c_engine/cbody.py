#!/usr/bin/env python3
"""cbody.c's algorithm as a stand-alone Python script (standard library only; imports nothing of rbcheck).

    python3 cbody.py [--broken-gyro] SCENARIO_JSON OUT_CSV

The fallback rbcheck's tests use where no C compiler exists; the same statements as cbody.c, in the
same order (see there for the scheme): semi-implicit Euler, explicit gyroscopic term, exp-map
quaternion update, forces from the start-of-step state. ``--broken-gyro`` flips the gyroscopic
term's sign, like cbody.c compiled with -DBROKEN_GYRO_SIGN.
"""
import json
import math
import sys


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def matvec(M, a):
    return [M[i][0] * a[0] + M[i][1] * a[1] + M[i][2] * a[2] for i in range(3)]


def mattvec(M, a):
    return [M[0][i] * a[0] + M[1][i] * a[1] + M[2][i] * a[2] for i in range(3)]


def inverse3(M):
    c00 = M[1][1] * M[2][2] - M[1][2] * M[2][1]
    c01 = M[1][2] * M[2][0] - M[1][0] * M[2][2]
    c02 = M[1][0] * M[2][1] - M[1][1] * M[2][0]
    det = M[0][0] * c00 + M[0][1] * c01 + M[0][2] * c02
    return [[c00 / det, (M[0][2] * M[2][1] - M[0][1] * M[2][2]) / det,
             (M[0][1] * M[1][2] - M[0][2] * M[1][1]) / det],
            [c01 / det, (M[0][0] * M[2][2] - M[0][2] * M[2][0]) / det,
             (M[0][2] * M[1][0] - M[0][0] * M[1][2]) / det],
            [c02 / det, (M[0][1] * M[2][0] - M[0][0] * M[2][1]) / det,
             (M[0][0] * M[1][1] - M[0][1] * M[1][0]) / det]]


def quat_matrix(q):
    w, x, y, z = q
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]


def quat_mul(a, b):
    return [a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]]


def quat_exp(r):
    th = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    t2 = th * th
    s = 0.5 - t2 / 48.0 + t2 * t2 / 3840.0 if th < 1e-4 else math.sin(0.5 * th) / th
    return [math.cos(0.5 * th), s * r[0], s * r[1], s * r[2]]


def forces(sc, x, v, R):
    m, fr = sc["body"]["mass"], sc["forces"]
    f = [m * fr["gravity"][i] - fr["linear_drag"] * v[i] for i in range(3)]
    tau = [0.0, 0.0, 0.0]
    for sp in fr["spring"]:
        r = matvec(R, sp["attach"])
        d = [x[i] + r[i] - sp["anchor"][i] for i in range(3)]
        L = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        if L == 0.0:
            continue
        fs = [-sp["stiffness"] * (L - sp["rest_length"]) * d[i] / L for i in range(3)]
        t = cross(r, fs)
        f = [f[i] + fs[i] for i in range(3)]
        tau = [tau[i] + t[i] for i in range(3)]
    for p in fr["point"]:
        F = matvec(R, p["force"]) if p["frame"] == "body" else list(p["force"])
        t = cross(matvec(R, p["point"]), F)
        f = [f[i] + F[i] for i in range(3)]
        tau = [tau[i] + t[i] for i in range(3)]
    for tq in fr["torque"]:
        T = matvec(R, tq["torque"]) if tq["frame"] == "body" else tq["torque"]
        tau = [tau[i] + T[i] for i in range(3)]
    return f, tau


def main(argv):
    broken = "--broken-gyro" in argv
    args = [a for a in argv if a != "--broken-gyro"]
    if len(args) != 2:
        sys.stderr.write("usage: cbody.py [--broken-gyro] SCENARIO_JSON OUT_CSV\n")
        return 2
    with open(args[0], encoding="utf-8") as fh:
        sc = json.load(fh)
    h, steps, m = sc["dt"], sc["steps"], sc["body"]["mass"]
    I = sc["body"]["inertia"]
    Iinv = inverse3(I)
    ini, fr = sc["initial"], sc["forces"]
    x, v, q, w = (list(ini["position"]), list(ini["velocity"]), list(ini["orientation"]),
                  list(ini["angular_velocity"]))
    gv, gw = fr["velocity_decay"], fr["angular_velocity_decay"]
    sign = 1.0 if broken else -1.0
    rows = ["t,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz"]

    def row(t):
        rows.append(",".join(repr(float(c)) for c in [t] + x + v + q + w))

    row(0.0)
    for n in range(1, steps + 1):
        R = quat_matrix(q)
        f, tau = forces(sc, x, v, R)
        v = [gv * (v[i] + h * f[i] / m) for i in range(3)]
        x = [x[i] + h * v[i] for i in range(3)]
        wB = mattvec(R, w)
        gyro = cross(wB, matvec(I, wB))
        tauB = mattvec(R, tau)
        tauB = [tauB[i] + sign * gyro[i] for i in range(3)]
        aW = matvec(R, matvec(Iinv, tauB))
        w = [gw * (w[i] + h * aW[i]) for i in range(3)]
        q = quat_mul(quat_exp([h * w[i] for i in range(3)]), q)
        nq = math.sqrt(sum(c * c for c in q))
        q = [c / nq for c in q]
        row(n * h)
    with open(args[1], "w", encoding="utf-8") as fh:
        fh.write("\n".join(rows) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
