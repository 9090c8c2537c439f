"""The resolved scenario: what every engine receives (``rbcheck show SCENARIO [--json]``).

:func:`resolved_scenario` turns a validated :class:`~cross_checks.scenario.Scenario` into a plain
dict in the scenario TOML's own key names, every alternative resolved, at the Δt of one run (the decay
factors too: e^(−kΔt) = γ^(Δt/dt)). A body whose frame origin is not at its COM (``body.com``, present only
then: absent means [0, 0, 0]) has its initial position and velocity given for that origin and its body points
from it; a body of welded parts lists them (``body.parts``, present only then).
Its keys, with their units and frames, and the informative extra keys: docs/engines.md, "The resolved
scenario".
"""
from __future__ import annotations

import json

import numpy as np

from reference_sim.quaternion import euler_zxy_from_quat, quat_conj, rotate
from reference_sim.state import Q, V, W, X

__all__ = ["resolved_scenario", "resolved_json", "format_resolved"]


def _vec(a) -> list:
    return [float(v) for v in np.asarray(a, dtype=float).ravel()]


def resolved_scenario(scenario, dt_s: float | None = None, duration_s: float | None = None) -> dict:
    """The resolved scenario (module docstring) for a run of step ``dt_s`` (default: the scenario's dt)
    over ``duration_s`` (default: the scenario's duration)."""
    import reference_sim
    from cross_checks.core.trajectory import COLUMNS

    p = scenario.problem
    dt = scenario.dt_s if dt_s is None else float(dt_s)
    T = scenario.duration_s if duration_s is None else float(duration_s)
    y0 = p.initial_packed()
    q0 = y0[Q]
    fm = p.forces
    gv, gw = fm.decay_factors(dt)     # e^(−kΔt) = γ^(Δt/dt), what the reference variants apply
    kv, kw = fm.decay_rates_per_s()
    c = getattr(scenario, "body_com_B_m", None)
    shift = np.zeros(3) if c is None else np.asarray(c, dtype=float)   # body points: from the frame's origin
    x0, v0 = y0[X], y0[V]
    if c is not None:
        from reference_sim.body import origin_state
        x0, v0 = origin_state(y0, c)
    out = {
        "name": scenario.name,
        "description": scenario.description,
        "duration": T,
        "dt": dt,
        "steps": scenario.n_steps(dt, T),
        "scenario_dt": scenario.dt_s,
        "dt_ladder": list(scenario.dt_ladder_s),
        "content_hash": scenario.content_hash,
        "rbcheck_version": reference_sim.__version__,
        "csv_columns": list(COLUMNS),
        "body": {
            "mass": float(p.body.mass_kg),
            "inertia": [_vec(row) for row in p.body.inertia_B],
            "principal_moments": _vec(np.linalg.eigvalsh(p.body.inertia_B)),
        },
        "initial": {
            "position": _vec(x0),
            "velocity": _vec(v0),
            "orientation": _vec(q0),
            "angular_velocity": _vec(y0[W]),
            "angular_velocity_body": _vec(rotate(quat_conj(q0), y0[W])),
        },
        "forces": {
            "gravity": _vec(fm.gravity_W),
            "linear_drag": float(fm.linear_drag_N_s_per_m),
            "velocity_decay": float(gv),
            "angular_velocity_decay": float(gw),
            "velocity_decay_rate": float(kv),
            "angular_velocity_decay_rate": float(kw),
            "spring": [{"anchor": _vec(s.anchor_W), "attach": _vec(s.attach_B + shift),
                        "stiffness": float(s.stiffness_N_per_m), "rest_length": float(s.rest_length_m)}
                       for s in fm.springs],
            "point": [{"force": _vec(f.force), "point": _vec(f.point_B + shift), "frame": f.frame}
                      for f in fm.point_forces],
            "torque": [{"torque": _vec(t.torque), "frame": t.frame} for t in fm.torques],
        },
    }
    if c is not None:   # the body frame's origin is not at the COM: said only then (absent means [0, 0, 0])
        out["body"]["com"] = _vec(c)
        out["initial"]["com_position"] = _vec(y0[X])
        out["initial"]["com_velocity"] = _vec(y0[V])
    parts = getattr(scenario, "body_parts", ())
    if parts:
        out["body"]["parts"] = [{"mass": float(pt.mass_kg), "com": _vec(pt.com_B_m),
                                 "inertia": [_vec(row) for row in pt.inertia_B]} for pt in parts]
    return out


def resolved_json(scenario, dt_s: float | None = None, duration_s: float | None = None) -> str:
    """:func:`resolved_scenario` as JSON text: floats printed to round-trip exactly, each vector (and
    each row of the inertia) on one line."""
    return _dumps(resolved_scenario(scenario, dt_s, duration_s), "") + "\n"


def _dumps(o, pad: str) -> str:
    inner = pad + "  "
    if isinstance(o, dict):
        if not o:
            return "{}"
        items = [f"{inner}{json.dumps(k)}: {_dumps(v, inner)}" for k, v in o.items()]
        return "{\n" + ",\n".join(items) + "\n" + pad + "}"
    if isinstance(o, list) and o and all(isinstance(v, (dict, list)) for v in o) and not all(
            isinstance(v, list) and all(not isinstance(x, (dict, list)) for x in v) for v in o):
        return "[\n" + ",\n".join(inner + _dumps(v, inner) for v in o) + "\n" + pad + "]"
    return json.dumps(o, allow_nan=False)


def _num(v) -> str:
    """12 significant digits (round-off such as 0.5000000000000001 hidden; --json has every digit)."""
    return f"{float(v) + 0.0:.12g}"


def _triple(v) -> str:
    """A vector for reading: components below 1e-12 of its largest are round-off, shown as 0."""
    big = max((abs(float(x)) for x in v), default=0.0)
    return "[" + ", ".join(_num(0.0 if abs(float(x)) < 1e-12 * big else x) for x in v) + "]"


def format_resolved(r: dict) -> str:
    """The resolved scenario for a person setting up their own simulator (units and frames spelled out)."""
    b, i, f = r["body"], r["initial"], r["forces"]
    origin = "COM" if "com" not in b else "body frame's origin"
    euler, locked = euler_zxy_from_quat(np.array(i["orientation"]))
    euler = np.round(euler, 12) + 0.0  # no "-0.0"
    lines = [f"{r['name']}: {r['description']}".rstrip(": "),
             f"  time      dt = {_num(r['dt'])} s, {r['steps']} steps "
             f"(t = 0 … {r['steps'] * r['dt']:.10g} s; scenario duration {_num(r['duration'])} s, "
             f"default dt {_num(r['scenario_dt'])} s)",
             f"            dt ladder {', '.join(_num(d) for d in r['dt_ladder'])} s",
             ("body (origin at the centre of mass)" if "com" not in b else
              f"body (its frame's origin NOT at the centre of mass: the COM at {_triple(b['com'])} m in body "
              "axes from it; the initial position and velocity are the origin's, body points from it)"),
             f"  mass      {_num(b['mass'])} kg",
             "  inertia   kg m², about the COM, body axes:"]
    lines += [f"            {_triple(row)}" for row in b["inertia"]]
    for k, pt in enumerate(b.get("parts", ())):
        lines.append(f"  part {k}    {_num(pt['mass'])} kg, its COM at {_triple(pt['com'])} m (body axes, "
                     "from "
                     f"the origin), inertia about it {', '.join(_triple(row) for row in pt['inertia'])} "
                     "kg m² "
                     "(welded: one rigid body)")
    lines += [f"  principal moments {_triple(b['principal_moments'])} kg m²",
              "initial state",
              f"  position          {_triple(i['position'])} m ({origin}, world)",
              f"  velocity          {_triple(i['velocity'])} m/s ({origin}, world)",
              f"  orientation       {_triple(i['orientation'])} (body→world quaternion w, x, y, z)",
              f"                    = Unity Euler angles (x, y, z) {_triple(euler)}° (rotation order Z, X, Y)"
              + (" — gimbal lock: z set to 0" if bool(locked) else ""),
              f"  angular velocity  {_triple(i['angular_velocity'])} rad/s (WORLD axes)",
              f"                    {_triple(i['angular_velocity_body'])} rad/s (body axes)",
              "forces",
              f"  gravity           {_triple(f['gravity'])} m/s²",
              f"  linear drag       {_num(f['linear_drag'])} N s/m (f = −c v at the COM)"]
    for key, what in (("velocity_decay", "v"), ("angular_velocity_decay", "ω")):
        if f[key] != 1.0:
            lines.append(f"  {key.replace('_', ' '):<17} {what} ← {_num(f[key])} {what} after each velocity "
                         f"update (per step of {_num(r['dt'])} s; rate k = {f[key + '_rate']:.10g} 1/s)")
    for s in f["spring"]:
        lines.append(f"  spring            anchor {_triple(s['anchor'])} m (world), attached "
                     f"at {_triple(s['attach'])} m (body, from the {origin}), "
                     f"k = {_num(s['stiffness'])} N/m, rest length {_num(s['rest_length'])} m")
    for p in f["point"]:
        lines.append(f"  point force       {_triple(p['force'])} N ({p['frame']} "
                     f"axes) at {_triple(p['point'])} m (body, from the {origin})")
    for t in f["torque"]:
        lines.append(f"  torque            {_triple(t['torque'])} N m ({t['frame']} axes)")
    lines.append(f"trajectory CSV columns: {','.join(r['csv_columns'])}")
    lines.append("(numbers rounded to 12 significant digits; `rbcheck show --json` gives every digit)")
    return "\n".join(lines)
