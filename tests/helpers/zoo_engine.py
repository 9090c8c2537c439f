#!/usr/bin/env python3
"""The invariance zoo's engine (tests only): examples/c_engine/cbody.py's scheme (semi-implicit Euler,
explicit gyroscopic term, exp-map quaternion) run as an engine file, correct or with one planted
representation bug.

    python3 zoo_engine.py MODE SCENARIO_JSON OUT_CSV

MODE ``correct``: cbody.py's step as it is. ``diagonal_inertia``: uses only the diagonal of the inertia tensor
(Avian #738's class: right for every diagonal body, wrong for every other). ``float32_positions``: stores the
position in float32 after every step while the engine file declares float64 (MuJoCo Warp #1546's class).
``ignores_com_offset``: reads the initial position and velocity and the body points as the COM's even when
``body.com`` says the body frame's origin is elsewhere. ``drops_welded_child``: of a body of welded parts
(``body.parts``), keeps every part's mass and the parallel-axis terms but drops the child parts' own inertia.
The correct engine integrates the COM: it converts the origin's state (``x = x_o + R c``,
``v = v_o + ω × R c``) and the points (``− c``), and composes the parts.
"""
import math
import struct
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples" / "c_engine"))
import cbody  # noqa: E402  (the example engine's functions: standard library only)


def f32(c: float) -> float:
    return struct.unpack("f", struct.pack("f", c))[0]


def composite_inertia(parts, com, drop_child=False):
    """The inertia about the composite COM ``com`` of welded parts (mass, com, 3×3 inertia each; their COMs
    and ``com`` from the body frame's origin): Σ I_i + m_i (|d|² E − d dᵀ), d = com_i − com; ``drop_child``:
    the parts after the first without their own inertia."""
    out = [[0.0] * 3 for _ in range(3)]
    for k, part in enumerate(parts):
        d = [part["com"][i] - com[i] for i in range(3)]
        dd = sum(e * e for e in d)
        for i in range(3):
            for j in range(3):
                own = 0.0 if (drop_child and k > 0) else part["inertia"][i][j]
                out[i][j] += own + part["mass"] * ((dd if i == j else 0.0) - d[i] * d[j])
    return out


def main(argv) -> int:
    import json
    mode, scenario_json, out_csv = argv
    with open(scenario_json, encoding="utf-8") as fh:
        sc = json.load(fh)
    h, steps, m = sc["dt"], sc["steps"], sc["body"]["mass"]
    inertia = sc["body"]["inertia"]
    body = sc["body"]
    c = body.get("com", [0.0, 0.0, 0.0]) if mode != "ignores_com_offset" else [0.0, 0.0, 0.0]
    if "parts" in body:
        inertia = composite_inertia(body["parts"], c, drop_child=mode == "drops_welded_child")
    for s in sc["forces"]["spring"]:
        s["attach"] = [s["attach"][i] - c[i] for i in range(3)]
    for p in sc["forces"]["point"]:
        p["point"] = [p["point"][i] - c[i] for i in range(3)]
    if mode == "diagonal_inertia":
        inertia = [[inertia[i][i] if i == j else 0.0 for j in range(3)] for i in range(3)]
    inv = cbody.inverse3(inertia)
    ini, fr = sc["initial"], sc["forces"]
    x, v, q, w = (list(ini["position"]), list(ini["velocity"]), list(ini["orientation"]),
                  list(ini["angular_velocity"]))
    r = cbody.matvec(cbody.quat_matrix(q), c)            # the origin's state -> the COM's
    wr = cbody.cross(w, r)
    x, v = [x[i] + r[i] for i in range(3)], [v[i] + wr[i] for i in range(3)]
    if mode == "float32_positions":
        x = [f32(c) for c in x]
    gv, gw = fr["velocity_decay"], fr["angular_velocity_decay"]
    rows = ["t,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz"]
    rows.append(",".join(repr(float(c)) for c in [0.0] + x + v + q + w))
    for n in range(1, steps + 1):
        R = cbody.quat_matrix(q)
        f, tau = cbody.forces(sc, x, v, R)
        v = [gv * (v[i] + h * f[i] / m) for i in range(3)]
        x = [x[i] + h * v[i] for i in range(3)]
        if mode == "float32_positions":
            x = [f32(c) for c in x]
        wB = cbody.mattvec(R, w)
        gyro = cbody.cross(wB, cbody.matvec(inertia, wB))
        tauB = cbody.mattvec(R, tau)
        tauB = [tauB[i] - gyro[i] for i in range(3)]
        aW = cbody.matvec(R, cbody.matvec(inv, tauB))
        w = [gw * (w[i] + h * aW[i]) for i in range(3)]
        q = cbody.quat_mul(cbody.quat_exp([h * w[i] for i in range(3)]), q)
        nq = math.sqrt(sum(c * c for c in q))
        q = [c / nq for c in q]
        rows.append(",".join(repr(float(c)) for c in [n * h] + x + v + q + w))
    with open(out_csv, "w", encoding="utf-8") as fh:
        fh.write("\n".join(rows) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
