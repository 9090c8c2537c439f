"""Shrinking a failing case to a minimal scenario that still fails, and confirming it with ``rbcheck sweep``
(docs/fuzz.md §3).

A failure has a *signature* (:func:`signature`). :func:`shrink` is a greedy shrinker in the spirit of
hypothesis's: each round proposes simpler scenarios (:func:`candidates`, simplest first), judges them in
small batches with the same pipeline that found the failure (a candidate outside the fairness bounds is
skipped by the pipeline and so never accepted) and keeps the first that still shows the signature, until
no candidate does. :func:`confirm` runs ``rbcheck sweep`` on the result (in this process, with the same
engines): the counterexample counts only if the sweep's own gates fail on it.
"""
from __future__ import annotations

import copy
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from cross_checks.fuzz.generate import to_toml
from cross_checks.fuzz.pipeline import evaluate_specs, steps_of
from reference_sim.quaternion import quat_from_euler_zxy, quat_from_matrix, quat_mul

__all__ = ["signature", "candidates", "shrink", "confirm", "sweep_gate_failures", "CHUNK"]

#: Candidates judged per batch while shrinking.
CHUNK = 8
_DIGITS = (1, 2, 3, 4, 6)


def signature(violation: dict) -> tuple:
    """(property, variants, quantity, outcome): what makes two failures the same finding (a shrunk case
    must keep all four, so that shrinking cannot wander from one failure to another)."""
    verdict = violation.get("verdict")
    outcome = verdict if verdict in ("failed", "diverged") else ""
    return violation["property"], tuple(violation["variants"]), violation.get("quantity") or "", outcome


def _has(outcome, sig) -> bool:
    return outcome is not None and any(signature(v) == sig for v in outcome.violations)


# --- candidates --------------------------------------------------------------------------------------

def _with_dt(spec, dt, n0):
    s = copy.deepcopy(spec)
    s["dt"] = dt
    s["dt_ladder"] = [dt, dt / 2.0, dt / 4.0]
    s["duration"] = n0 * dt
    return s


def _round(x, digits):
    if isinstance(x, float):
        return float(f"{x:.{digits}g}") if math.isfinite(x) and x != 0.0 else x
    if isinstance(x, list):
        return [_round(e, digits) for e in x]
    if isinstance(x, dict):
        return {k: _round(v, digits) for k, v in x.items()}
    return x


def _principal_frame(spec):
    """The same motion with the body given by its principal moments in its principal frame P: the
    orientation becomes q_WP = q_WB ⊗ q_BP and every body-frame vector and point is rotated into P
    (a particle body becomes its mass and tensor about the COM first)."""
    from reference_sim.body import RigidBody, check_inertia, principal_axes
    s = copy.deepcopy(spec)
    b, ini, f = s["body"], s.setdefault("initial", {}), s.get("forces", {})
    com = np.zeros(3)
    if "particles" in b:
        body, com = RigidBody.from_particles(np.array(b["particles"], dtype=float))
        mass, I = body.mass_kg, body.inertia_B
    else:
        mass, I = float(b["mass"]), check_inertia(b["inertia"])
    moments, R = principal_axes(I)
    s["body"] = {"mass": mass, "inertia": moments.tolist()}
    q = (quat_from_euler_zxy(ini.pop("euler_zxy_deg")) if "euler_zxy_deg" in ini
         else np.asarray(ini.get("orientation", [1.0, 0.0, 0.0, 0.0]), dtype=float))
    ini["orientation"] = quat_mul(q / np.linalg.norm(q), quat_from_matrix(R)).tolist()
    if "angular_velocity_body" in ini:
        ini["angular_velocity_body"] = (R.T @ np.asarray(ini["angular_velocity_body"])).tolist()
    for sp in f.get("spring", []):
        sp["attach"] = (R.T @ (np.asarray(sp.get("attach", com), dtype=float) - com)).tolist()
    for pf in f.get("point", []):
        pf["point"] = (R.T @ (np.asarray(pf.get("point", com), dtype=float) - com)).tolist()
        if pf.get("frame") == "body":
            pf["force"] = (R.T @ np.asarray(pf["force"], dtype=float)).tolist()
    for t in f.get("torque", []):
        if t.get("frame") == "body":
            t["torque"] = (R.T @ np.asarray(t["torque"], dtype=float)).tolist()
    return s


def candidates(spec: dict) -> list:
    """Simpler versions of ``spec``, simplest first: [(what changed, spec)]."""
    out = []
    n0 = steps_of(spec)
    if n0 >= 8:
        out.append((f"duration halved ({n0 // 2} steps at dt)", _with_dt(spec, spec["dt"], n0 // 2)))
    forces = spec.get("forces", {})
    for key in forces:
        s = copy.deepcopy(spec)
        del s["forces"][key]
        out.append((f"forces.{key} removed", s))
        if isinstance(forces[key], list) and len(forces[key]) > 1:
            for i in range(len(forces[key])):
                s = copy.deepcopy(spec)
                del s["forces"][key][i]
                out.append((f"forces.{key}[{i}] removed", s))
    body = spec["body"]
    if "particles" in body or np.ndim(body.get("inertia")) == 2:
        out.append(("body given by its principal moments in its principal frame (the same motion)",
                    _principal_frame(spec)))
    for key in list(spec.get("initial", {})):
        s = copy.deepcopy(spec)
        del s["initial"][key]
        out.append((f"initial.{key} at its default", s))
    for d in _DIGITS:
        s = _round(copy.deepcopy(spec), d)
        s["dt"] = _round(float(spec["dt"]), d)
        s = _with_dt(s, s["dt"], n0)
        if s != spec:
            out.append((f"every number rounded to {d} significant digit(s)", s))
    for table in ("body", "initial", "forces"):
        for key, value in spec.get(table, {}).items():
            if isinstance(value, list) and value and isinstance(value[0], dict):
                continue
            for d in _DIGITS:
                s = copy.deepcopy(spec)
                s[table][key] = _round(value, d)
                if s != spec:
                    out.append((f"{table}.{key} rounded to {d} digit(s)", s))
                    break
    return out


# --- shrinking ---------------------------------------------------------------------------------------------

def shrink(spec: dict, sig: tuple, variants, *, deadline: float | None = None,
           max_rounds: int = 60, keep=None) -> tuple:
    """The smallest scenario dict reachable from ``spec`` that still shows ``sig``: (spec, [steps taken]).

    ``variants``: what to run (the signature's variants suffice). ``deadline``: a time.monotonic() after
    which shrinking stops where it is (the case then is simply less small). ``keep(spec, outcome)``: a
    further condition a smaller case must meet (campaign: the same explained-or-not finding)."""
    steps = []
    current = spec
    for _ in range(max_rounds):
        cands = candidates(current)
        accepted = None
        for k in range(0, len(cands), CHUNK):
            if deadline is not None and time.monotonic() > deadline:
                return current, steps
            chunk = cands[k:k + CHUNK]
            outcomes = evaluate_specs([c for _, c in chunk], variants)
            for (what, cand), o in zip(chunk, outcomes):
                if _has(o, sig) and (keep is None or keep(cand, o)):
                    accepted = (what, cand)
                    break
            if accepted:
                break
        if accepted is None:
            return current, steps
        steps.append(accepted[0])
        current = accepted[1]
    return current, steps


# --- confirmation by rbcheck sweep --------------------------------------------------------------------------

def sweep_gate_failures(summary) -> list:
    """The sentences with which ``rbcheck sweep`` exits 1 on this summary (cli's gates: a verdict that
    contradicts its expectation, two same-scheme variants that differ, a failed run)."""
    out = [f"{r['engine']} on {r['scenario']}: {r['quantity'].replace('_', ' ')} {r['assessment']}"
           for r in summary.get("convergence", []) if r.get("matches_expectation") is False]
    out += [f"{a['a']} and {a['b']} differ on {a['scenario']} (should be the same scheme)"
            for a in summary.get("agreement", []) if not a.get("agrees")]
    n_failed = summary.get("run", {}).get("failed_runs", 0)
    if n_failed:
        out.append(f"{n_failed} run(s) failed (status 'failed' in results.csv)")
    return out


def confirm(spec: dict, variants) -> list:
    """Run ``rbcheck sweep`` (in this process, one worker, no cache) on ``spec`` with ``variants``:
    the gate failures that make it exit 1 ([] when it passes)."""
    from cross_checks.scenario import load_scenario
    from cross_checks.sweep import run_sweep
    with tempfile.TemporaryDirectory(prefix="rbcheck-fuzz-confirm-") as tmp:
        path = Path(tmp) / f"{spec['name']}.toml"
        path.write_text(to_toml(spec), encoding="utf-8")
        summary = run_sweep([load_scenario(str(path))], list(variants), Path(tmp) / "out", jobs=1,
                            use_cache=False, progress=False)
    return sweep_gate_failures(summary)
