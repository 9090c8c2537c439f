"""Standalone reproducers (``rbcheck repro``; docs/repro.md): one Python script per claim about a variant on a
scenario, importing only the engine and NumPy, that an engine's maintainers can run without rbcheck.

The script is made of three parts, two of them rbcheck's own code placed line for line, compacted
(:mod:`cross_checks.sweep.repro_text`: docstrings, comments and unreached definitions left out, and what the
script's numbers never reach, :mod:`cross_checks.sweep.repro_slice`):

1. the engine's world (cross_checks/engines/worlds/<engine>.py: the model the adapter builds, with the same
   neutralised defaults, in the engine's own API — the adapter imports it, so it is not a copy);
2. the measurement (:mod:`cross_checks.sweep.repro_measure`: the run with the forces held, and the claim's
   number);
3. the numbers: the scenario's body, initial state and forces, and the reference values the claim needs
   (the exact final state at each Δt, the round-off floors, the invariants, the transformed scenario and the
   allowances), then ``sys.exit(main_CLAIM(world, globals()))``.

It prints the engine's, NumPy's and Python's versions and the platform, then the measured value beside the
expected one, and exits 1 while the defect holds, 0 when it does not. Writing a script runs it here (in
this process, the same code): a claim that does not hold is written anyway and said so.

Claims: ``order QUANTITY`` (the fitted order over the variant's judged Δt ladder against its declared
order), ``drift`` (a long run: energy, |L|, the separatrix distance), ``gyroscopic`` (the torque-free flip of
an intermediate-axis spin is missing), ``invariance TRANSFORM`` (the transformed scenario, mapped back,
moves as the original within the sweep's allowance; TRANSFORM as invariance.csv names it).
"""
from __future__ import annotations

import contextlib
import importlib
import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cross_checks.core import tolerances as tol
from cross_checks.core.quantities import QUANTITIES
from cross_checks.sweep.repro_text import compact

__all__ = ["ENGINES", "CLAIMS", "ReproError", "Repro", "parse_claim", "reproducer", "write_reproducer",
           "findings_claims", "write_sweep_reproducers", "file_name", "map_numbers", "TRANSFORM_NAMES"]

#: Engines that can write reproducers: engine -> (the distributions whose versions the script prints, the
#: world modules it embeds in order, the adapter module, the module whose ``body_spec`` gives the bodies and,
#: where the engine takes a body off its COM or of welded parts, ``body_entry`` the scenario's body then:
#: the script's world is then ``form_world``; worlds/com.py holds the conversions between the COM and the
#: body origin that these worlds share).
_W, _A = "cross_checks.engines.worlds.", "cross_checks.engines."
ENGINES = {
    "mujoco": (("mujoco",), (_W + "com", _W + "mujoco"), _A + "mujoco_engine", _A + "mujoco_engine"),
    "rapier": (("rapier3d",), (_W + "rapier",), _A + "rapier_engine", _A + "rapier_engine"),
    "pybullet": (("pybullet",), (_W + "pybullet",), _A + "pybullet_engine", _A + "pybullet_engine"),
    "mjx": (("mujoco-mjx", "mujoco", "jax"), (_W + "mujoco", _W + "mjx"), _A + "mjx_engine",
            _A + "mujoco_engine"),
    "brax": (("brax", "jax", "mujoco"), (_W + "brax",), _A + "brax_engine", _A + "brax_engine"),
    "physx": (("sapien",), (_W + "physx",), _A + "physx_engine", _A + "physx_engine"),
    "dart": (("dartpy",), (_W + "com", _W + "dart"), _A + "dart_engine", _A + "dart_engine"),
    "drake": (("drake",), (_W + "com", _W + "drake"), _A + "drake_engine", _A + "drake_engine"),
    "mujoco_warp": (("mujoco-warp", "warp-lang", "mujoco"), (_W + "mujoco", _W + "mujoco_warp"),
                    _A + "mujoco_warp_engine", _A + "mujoco_engine"),
    "jaxsim": (("jaxsim", "jax"), (_W + "jaxsim",), _A + "jaxsim_engine", _A + "jaxsim_engine"),
    "newton": (("newton", "warp-lang"), (_W + "newton",), _A + "newton_engine", _A + "newton_engine"),
    "genesis": (("genesis-world", "quadrants", "torch"), (_W + "genesis",), _A + "genesis_engine",
                _A + "genesis_engine"),
}
#: claim -> the word it takes ("" for none).
CLAIMS = {"order": "QUANTITY", "drift": "", "gyroscopic": "", "invariance": "TRANSFORM"}


class ReproError(ValueError):
    """A claim or a variant/scenario a reproducer cannot be written for: one line (the CLI's exit 2)."""


@dataclass
class Repro:
    """A written reproducer: its ``text``, whether the defect ``holds`` here, and the script's ``output``
    (what it printed when run here)."""

    text: str
    holds: bool | None
    output: str
    claim: str

    @property
    def summary(self) -> str:
        """The script's verdict line (its last)."""
        lines = self.output.strip().splitlines()
        return lines[-1] if lines else ""


def parse_claim(words) -> tuple:
    """``["order", "orientation"]`` -> ``("order", "orientation")``; ``["drift"]`` -> ``("drift", "")``.
    ReproError (one line) for an unknown claim, a missing or unknown word."""
    words = list(words or [])
    if not words:
        raise ReproError("--claim: give a claim: " + ", ".join(f"{c} {w}".strip() for c, w in CLAIMS.items()))
    kind, rest = words[0], words[1:]
    if kind not in CLAIMS:
        raise ReproError(f"--claim: unknown claim {kind!r}; claims: "
                         + ", ".join(f"{c} {w}".strip() for c, w in CLAIMS.items()))
    need = CLAIMS[kind]
    if kind == "invariance":
        if not rest:
            raise ReproError(f"--claim invariance: give a TRANSFORM (as invariance.csv names it: "
                             f"{'; '.join(TRANSFORM_NAMES)})")
        return kind, _transform(rest).label
    if need and len(rest) != 1:
        raise ReproError(f"--claim {kind}: give one {need} (e.g. --claim {kind} orientation)")
    if not need and rest:
        raise ReproError(f"--claim {kind} takes no word, got {' '.join(rest)!r}")
    arg = rest[0] if rest else ""
    if kind == "order" and arg not in QUANTITIES:
        raise ReproError(f"--claim order: unknown quantity {arg!r}; quantities: {', '.join(QUANTITIES)}")
    return kind, arg


def _default_transforms() -> dict:
    """The sweep's transforms by their names (invariance.csv's ``transform magnitude``)."""
    from cross_checks.scenario.transforms import default_transforms
    return {t.label: t for t in default_transforms()}


#: The invariance claim's TRANSFORM names: invariance.csv's transform and magnitude, as the sweep names them.
TRANSFORM_NAMES = tuple(_default_transforms())
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _transform(words):
    """The sweep's transform named by ``words`` (``["scale", "k=0.01", "mu=0.01"]``, ``["translation",
    "1e4"]``: its kind, then its magnitude's numbers, the unit optional; the kind alone where the sweep has
    one of it); ReproError (one line, naming the known ones) otherwise."""
    from cross_checks.scenario.transforms import TRANSFORM_KINDS
    words = " ".join(words).split()
    known = _default_transforms()
    said = f"known: {'; '.join(known)}"
    if not words or words[0] not in TRANSFORM_KINDS:
        raise ReproError(f"--claim invariance: unknown transform {' '.join(words)!r}; {said}")
    same = [t for t in known.values() if t.kind == words[0]]
    if len(words) == 1:
        if len(same) == 1:
            return same[0]
        raise ReproError(f"--claim invariance {words[0]}: give its magnitude; {said}")
    want = [float(v) for v in _NUMBER.findall(" ".join(words[1:]))]
    for t in same:
        if want and want == [float(v) for v in _NUMBER.findall(t.magnitude)]:
            return t
    raise ReproError(f"--claim invariance: unknown transform {' '.join(words)!r}; {said}")


def _engine(variant_name):
    """(engine, variant, distributions, world module names, adapter module, body_spec's module) of a Resolved
    ``variant_name``; ReproError when the engine cannot write one."""
    from cross_checks.engines import get_adapter
    from cross_checks.engines.external import ExternalEngine
    engine, variant = variant_name.engine, variant_name.variant
    try:
        adapter = get_adapter(engine)
    except Exception as exc:  # noqa: BLE001 - EngineUnavailable: the engine's own words
        raise ReproError(f"{variant_name}: {exc}") from None
    if isinstance(adapter, ExternalEngine):
        raise ReproError(f"{engine} is an engine file: it cannot write a reproducer; its command is the "
                         "reproducer (docs/repro.md)")
    if engine == "reference":
        raise ReproError("reference is rbcheck's own NumPy implementation, not an engine with maintainers to "
                         "report to: `rbcheck check` and `rbcheck sweep` show its numbers (docs/repro.md)")
    if engine not in ENGINES:
        raise ReproError(f"{engine} cannot write reproducers yet; these can: {', '.join(ENGINES)} "
                         "(docs/repro.md)")
    dists, worlds, adapter_mod, spec_mod = ENGINES[engine]
    return (engine, variant, dists, list(worlds), importlib.import_module(adapter_mod),
            importlib.import_module(spec_mod))


def _floats(a) -> str:
    """Numbers as Python literals that read back bit for bit (repr of floats), nested lists kept, None."""
    if a is None:
        return "None"
    if isinstance(a, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_floats(x) for x in (a.tolist() if isinstance(a, np.ndarray) else a)) + "]"
    return repr(float(a))


def _assignments(values: dict, width: int = 110) -> list:
    """``NAME = value`` lines of ``values`` (name -> its literal), short ones gathered on a line as one tuple
    assignment (``A, B = 1.0, 2.0``) while the line stays within ``width``: the numbers, compactly."""
    lines, names, vals = [], [], []
    for k, v in list(values.items()) + [("", "")]:
        joined = f"{', '.join(names + [k])} = {', '.join(vals + [v])}"
        if names and (not k or len(joined) > width or "\n" in v):
            lines.append(f"{', '.join(names)} = {', '.join(vals)}")
            names, vals = [], []
        if k:
            names.append(k)
            vals.append(v)
    return lines


def _source(module: str) -> str:
    """A module's text, as it is; read from its file, not imported (a sweep's parent must not start JAX)."""
    import importlib.util
    return Path(importlib.util.find_spec(module).origin).read_text(encoding="utf-8")


def _constant_forces(scenario, engine: str) -> tuple:
    """The force (minus the weight where the engine applies gravity) and torque held over a run, world axes
    (N, N m); ReproError when the scenario's forces change within the run."""
    from cross_checks.engines.loop import Harness
    fm = scenario.problem.forces
    if fm.state_dependent or fm.has_decay:
        raise ReproError(f"scenario {scenario.name}: its forces change with the state (springs, drag, "
                         "body-frame or point forces, decay); a reproducer holds the forces constant: "
                         "choose a torque-free or constant-force scenario")
    refuses = getattr(importlib.import_module(ENGINES[engine][2]), "repro_refuses", None)
    why = refuses(scenario) if refuses else ""
    if why:
        raise ReproError(f"scenario {scenario.name}: {why}")
    from cross_checks.engines import get_adapter
    h = Harness([scenario], scenario.dt_s, get_adapter(engine).applies_gravity)   # the registered engine's
    f, tau = h.wrench(scenario.problem.initial_packed()[None])
    return f[0], tau[0]


def reproducer(variant_name: str, scenario, claim_words, *, command: str = "", run: bool = True) -> Repro:
    """The reproducer of ``claim_words`` (e.g. ``["order", "orientation"]``) about ``variant_name`` on
    ``scenario`` (a parsed Scenario), run here (``run``; else ``holds`` is None: the sweep, which measured
    it already): a :class:`Repro`. ReproError for what it cannot be written for (one line)."""
    import reference_sim
    from cross_checks.engines import UnknownVariant, resolve
    kind, arg = parse_claim(claim_words)
    try:
        variant_name = resolve(variant_name, strict=True)   # once: every part below reads what it declares
    except UnknownVariant as exc:
        raise ReproError(str(exc)) from None
    engine, variant, dists, world_mods, adapter_mod, spec_mod = _engine(variant_name)
    f_W, tau_W = _constant_forces(scenario, engine)
    body = spec_mod.body_spec(scenario.problem.body)
    common = {"DIST": repr(dists), "VARIANT": repr(variant),
              "BODIES": "[(" + ", ".join(_floats(x) for x in body) + ")]",
              "GRAVITY_W": _floats(scenario.problem.forces.gravity_W),
              "Y0": _floats(scenario.problem.initial_packed()),
              "F_W": _floats(f_W), "TAU_W": _floats(tau_W)}
    claim_text = f"{kind} {arg}".strip()
    world_fn = "world"
    if kind == "invariance":
        data, expect, world_fn = _invariance_data(variant_name, scenario, arg, engine, spec_mod)
    else:
        data, expect = {"order": _order_data, "drift": _drift_data, "gyroscopic": _gyro_data}[kind](
            variant_name, scenario, arg)
    command = command or f"rbcheck repro {variant_name} {scenario.name} --claim {claim_text}"
    header = (f'"""{variant_name} on {scenario.name}: {expect}\n'
              f"Written by rbcheck {reference_sim.__version__} ({command}); needs only numpy and "
              f"{', '.join(dists)}.\nExit 1 while the defect holds, 0 when it does not. The code: rbcheck's "
              + "".join(f"engines/worlds/{m.rsplit('.', 1)[1]}.py, " for m in world_mods
                        if not m.endswith(".com"))
              + ("engines/worlds/com.py, " if world_fn == "form_world" else "")
              + 'sweep/repro_measure.py, compacted."""\n')
    lines = _assignments({**common, **data})
    main = f"main_{kind}"
    tail = ("# the scenario (SI units; states [x_W, v_W, q_WB (w x y z), ω_W]) and the reference values\n"
            + "\n".join(lines) + "\n"
            + f"if __name__ == \"__main__\": sys.exit({main}({world_fn}, globals()))\n")
    modules = [*world_mods, "cross_checks.sweep.repro_measure"]
    text = header + compact(["import sys\n"] + [_source(m) for m in modules], tail)
    if not run:
        return Repro(text=text, holds=None, output="", claim=claim_text)
    start = getattr(adapter_mod, "start_for_repro", None)   # an engine rbcheck starts its own way first
    if start is not None:
        start()
    ns = {"__name__": "rbcheck_repro"}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(text, f"<repro {variant_name} {scenario.name}>", "exec"), ns)   # noqa: S102 - our own
        code = ns[main](ns[world_fn], ns)
    return Repro(text=text, holds=bool(code), output=out.getvalue(), claim=claim_text)


def _order_data(variant_name, scenario, quantity) -> tuple:
    from cross_checks.analysis import metrics as M
    from cross_checks.analysis.expectations import judged_ladder_s, machine_epsilon, nominal_order
    from cross_checks.core.quantities import quantity_scales
    from cross_checks.scenario.references import error_amplification, reference_error, reference_solution
    if scenario.long_run:
        raise ReproError(f"scenario {scenario.name} is a long run (no Δt ladder): its claim is drift")
    declared = nominal_order(variant_name)
    if declared is None:
        raise ReproError(f"{variant_name} declares no order: an order claim needs one")
    dts = list(judged_ladder_s(scenario, variant_name))
    steps = [scenario.n_steps(h) for h in dts]
    y_all, label = reference_solution(scenario, np.linspace(0.0, scenario.duration_s, 201))
    scales = quantity_scales(y_all)
    amp = error_amplification(scenario, scales).get(quantity, 1.0)
    refs, floors = [], []
    for h, n in zip(dts, steps):
        y_ref = reference_solution(scenario, np.array([0.0, n * h]))[0][-1]
        ref_err = reference_error(scenario, y_ref, label, scales)[quantity]
        refs.append(y_ref)
        floors.append(M.roundoff_floor(scales[quantity], n, label, reference_error=ref_err, amplification=amp,
                                       quantity=quantity, eps=machine_epsilon(variant_name)))
    data = {"QUANTITY": repr(quantity), "DT_S": _floats(dts), "STEPS": repr(steps),
            "Y_REF": (f"[{_floats(refs[0])}] * {len(refs)}" if all(np.array_equal(r, refs[0]) for r in refs)
                      else _floats(refs)),
            "FLOORS": _floats(floors), "DECLARED": repr(float(declared)),
            "ORDER_TOL": repr(tol.SWEEP_ORDER_TOL), "RESOLVED": repr(tol.RESOLVED_ABOVE_FLOOR)}
    return data, (f"{quantity} converges at order {declared:g} (declared) over Δt = "
                  f"{', '.join(f'{h:g}' for h in dts)} s? Reference: {label}.")


def _has_form_world(engine: str) -> bool:
    """Whether ``engine``'s world (the last module it embeds) builds a body off its COM or of welded parts."""
    return "\ndef form_world(" in _source(ENGINES[engine][1][-1])


def _invariance_data(variant_name, scenario, label, engine, spec_mod) -> tuple:
    """``(numbers, expectation, world function)``: the transformed scenario's numbers as the invariance
    machinery builds them (transforms.apply), the map back, and the allowances and step orders the sweep
    judges with (sweep.invariance, analysis.judge.invariance_allowance) at the scenario's Δt and its
    refinements; the script's world is ``form_world`` where the transformed body is off its COM or of
    welded parts (the adapter's ``body_entry`` of it, as the adapter builds it), else ``world``."""
    from cross_checks.analysis.judge import invariance_allowance
    from cross_checks.core.quantities import QUANTITIES, UNITS, quantity_scales
    from cross_checks.scenario.references import error_amplification, reference_solution
    from cross_checks.scenario.transforms import (
        TransformRefused,
        apply,
    )
    from cross_checks.sweep.invariance import step_order
    t = _default_transforms()[label]
    if scenario.long_run:
        raise ReproError(f"scenario {scenario.name} is a long run: the sweep does not transform long runs")
    try:
        tsc = apply(t, scenario)
    except TransformRefused as exc:
        raise ReproError(f"--claim invariance {label}: refused on {scenario.name}: {exc.field}: "
                         f"{exc.reason}") from None
    why = variant_name.cannot_express(tsc)
    if why:
        raise ReproError(f"{variant_name} cannot express {label} on {scenario.name} ({why}): the sweep says "
                         "'cannot express', not a defect")
    world_fn = "world"
    body_T = spec_mod.body_spec(tsc.problem.body)
    if getattr(tsc, "body_com_B_m", None) is not None or getattr(tsc, "body_parts", ()):
        # the body off its COM or of welded parts: the world's form_world takes it as the adapter builds it
        # (body_entry), converting the state between the COM and the body origin (worlds/com.py)
        entry = getattr(spec_mod, "body_entry", None)
        if entry is None or not _has_form_world(engine):   # an adapter that builds it, a world that does not
            can = [e for e in ENGINES if _has_form_world(e)]
            raise ReproError(f"--claim invariance {t.kind}: {engine}'s world cannot build a body off its COM "
                             f"or of welded parts; these can: {', '.join(can)}")
        world_fn, body_T = "form_world", entry(tsc)
    f_T, tau_T = _constant_forces(tsc, engine)
    traits = variant_name.traits
    dt, T = scenario.dt_s, scenario.duration_s
    dts = [dt] + [dt / r for r in tol.INVARIANCE_REFINEMENTS]
    steps = [scenario.n_steps(h, T) for h in dts]
    y_ref, _ = reference_solution(scenario, dt * np.arange(scenario.n_steps() + 1))
    scales = quantity_scales(y_ref)
    amp = error_amplification(scenario, scales)
    allowances, base0 = [], None
    for h, n in zip(dts, steps):
        base, off = invariance_allowance(scales, amp, n, precision=getattr(traits, "precision", "float64"),
                                         rounding_factor=getattr(traits, "rounding_factor", 1.0),
                                         offset_m=t.position_offset_m(), dt_s=h,
                                         differenced=getattr(traits, "velocity_from_positions", False))
        base0 = base0 or base
        allowances.append({q: base[q] + off[q] for q in QUANTITIES})
    data = {"SCENARIO": repr(scenario.name), "TRANSFORM": repr(label),
            "BODIES_T": "[(" + ", ".join(_floats(x) for x in body_T) + ")]",
            "GRAVITY_T": _floats(tsc.problem.forces.gravity_W), "Y0_T": _floats(tsc.problem.initial_packed()),
            "F_T": _floats(f_T), "TAU_T": _floats(tau_T),
            **{k: _floats(v) for k, v in map_numbers(t).items()},
            "DT_S": _floats(dts), "STEPS": repr(steps),
            "BASE": "{" + ", ".join(f"{q!r}: {base0[q]!r}" for q in QUANTITIES) + "}",
            "ALLOWANCE": "[" + ", ".join("{" + ", ".join(f"{q!r}: {a[q]!r}" for q in QUANTITIES) + "}"
                                         for a in allowances) + "]",
            "STEP_ORDER": "{" + ", ".join(f"{q!r}: {step_order(scenario, variant_name, q)!r}"
                                          for q in QUANTITIES) + "}",
            "UNITS": repr({q: UNITS[q] for q in QUANTITIES})}
    return data, (f"the same physics written another way ({label}: transforms.py) must move the same once "
                  f"mapped back: judged as rbcheck sweep --invariance judges it at Δt = {dt:g} s (and at "
                  f"{', '.join(f'{h:g}' for h in dts[1:])} s where it fails there)"), world_fn


def map_numbers(t) -> dict:
    """The numbers with which the script's ``map_back`` (repro_measure) undoes transform ``t``: ``MAP_D`` (m),
    ``MAP_R`` = R(r), ``MAP_R_INV`` = r⁻¹, ``MAP_P_INV`` = p⁻¹, ``MAP_K``; each transform sets one of
    d, r, p, k (a translation, a world rotation, a body frame, a scale), the others are the identity."""
    from cross_checks.scenario.transforms import BodyFrame, Scale, Translation, WorldRotation
    from reference_sim.quaternion import matrix_from_quat, quat_conj
    one = np.array([1.0, 0.0, 0.0, 0.0])
    r = np.asarray(t.r_wxyz, dtype=float) if isinstance(t, WorldRotation) else one
    p = np.asarray(t.p_wxyz, dtype=float) if isinstance(t, BodyFrame) else one
    return {"MAP_D": np.asarray(t.d_W_m, dtype=float) if isinstance(t, Translation) else np.zeros(3),
            "MAP_R": matrix_from_quat(r), "MAP_R_INV": quat_conj(r), "MAP_P_INV": quat_conj(p),
            "MAP_K": float(t.k) if isinstance(t, Scale) else 1.0}


def _torque_free(scenario, what: str) -> None:
    from cross_checks.analysis.metrics import conserved
    c = conserved(scenario.problem.forces)
    if not (c["energy"][0] and c["angular_momentum"][0]):
        raise ReproError(f"scenario {scenario.name}: a {what} claim needs a torque-free scenario whose "
                         f"energy and angular momentum are conserved "
                         f"({c['energy'][1] or c['angular_momentum'][1]})")


def _drift_data(variant_name, scenario, _arg) -> tuple:
    _torque_free(scenario, "drift")
    inertia = scenario.problem.body.inertia_B
    I2 = float(np.linalg.eigvalsh(inertia)[1])
    n = scenario.n_steps()
    data = {"DT": repr(float(scenario.dt_s)), "N": repr(n), "INERTIA_B": _floats(inertia), "I2": repr(I2),
            "END_FRACTION": repr(tol.LONG_RUN_END_FRACTION), "MIN_CHANGE": repr(tol.SECULAR_MIN_CHANGE),
            "TREND_TO_SCATTER": repr(tol.SECULAR_MIN_TREND_TO_SCATTER)}
    return data, (f"does a torque-free run of {n} steps of {scenario.dt_s:g} s keep its energy, |L| and its "
                  "separatrix distance δ = (2E I₂ − |L|²)/|L|²?")


def _gyro_data(variant_name, scenario, _arg) -> tuple:
    from cross_checks.scenario.references import reference_solution
    from cross_checks.sweep import repro_measure as rm
    from reference_sim.quaternion import quat_from_matrix
    _torque_free(scenario, "gyroscopic")
    body = scenario.problem.body
    moments, R_BP = body.principal_axes()
    q_BP = np.array([1.0, 0.0, 0.0, 0.0]) if body.is_diagonal() else quat_from_matrix(R_BP)
    axis = 1 if not body.is_diagonal() else int(np.argsort(np.diag(body.inertia_B), kind="stable")[1])
    dt, n = float(scenario.dt_s), scenario.n_steps()
    y_ref, label = reference_solution(scenario, dt * np.arange(n + 1))
    flip = rm.first_flip_s(y_ref, q_BP, axis, dt)
    if flip is None:
        raise ReproError(f"scenario {scenario.name}: the reference ({label}) does not flip within "
                         f"{scenario.duration_s:g} s: a gyroscopic claim needs a torque-free spin near the "
                         "intermediate axis (e.g. tennis_racket)")
    data = {"DT": repr(dt), "N": repr(n), "Q_BP": _floats(q_BP), "AXIS": repr(axis), "FLIP_S": repr(flip)}
    return data, (f"does the torque-free spin near the intermediate axis flip (at t = {flip:.4g} s, "
                  f"{label})?")


def write_reproducer(repro: Repro, out) -> Path:
    """Write ``repro``'s script to ``out`` atomically (executable); returns the path."""
    from cross_checks.core.files import atomic_write_text
    out = Path(out)
    atomic_write_text(out, repro.text)
    out.chmod(0o755)
    return out


#: The quantity a contradicted order's reproducer states, when several of a variant's are contradicted.
_QUANTITY_PREFERENCE = ("orientation", "angular_velocity", "position", "velocity")


def findings_claims(summary: dict, scenarios) -> list:
    """``[(variant, scenario, claim words)]``: the sweep's findings a reproducer states, once per variant and
    scenario — every contradicted order (``order QUANTITY``, the quantity of :data:`_QUANTITY_PREFERENCE`
    first), every long run with a finding (``drift``: toward, away from or across the separatrix, or
    diverged), every expected non-convergence of a variant without a gyroscopic term on a torque-free
    scenario (``gyroscopic``), and every order the variant's traits expect below the one it declares (an
    engine's known shortfall, e.g. MJX's RK4 attitude at order 2: ``order QUANTITY``) where the forces are
    constant; and every broken invariance, an engine's declared known finding included (``invariance
    TRANSFORM``, one per transform). The reference's own
    schemes (``reference:``) are rbcheck's: none."""
    from cross_checks.analysis.metrics import conserved
    from cross_checks.engines import resolve
    by_name = {sc.name: sc for sc in scenarios}
    out: dict = {}
    recs = summary.get("convergence") or []
    for r in sorted((r for r in recs if r.get("matches_expectation") is False),
                    key=lambda r: _QUANTITY_PREFERENCE.index(r["quantity"])):
        out.setdefault((r["engine"], r["scenario"]), ["order", r["quantity"]])
    declared = {v["name"]: v.get("declared_order") for v in summary.get("variants") or []}
    for r in sorted(recs, key=lambda r: _QUANTITY_PREFERENCE.index(r["quantity"])):
        key = (r["engine"], r["scenario"])
        sc = by_name.get(r["scenario"])
        if key in out or sc is None:
            continue
        fm = sc.problem.forces
        c = conserved(fm)
        gyro = resolve(r["engine"]).traits.gyroscopic_term   # a name read from the sweep's summary
        if (r.get("expected_verdict") == "does_not_converge" and not gyro
                and c["energy"][0] and c["angular_momentum"][0]):
            out[key] = ["gyroscopic"]
        elif (r.get("expected_verdict") == "converges" and r.get("matches_expectation")
              and r.get("expected_order") is not None and declared.get(r["engine"]) is not None
              and r["expected_order"] < declared[r["engine"]] - tol.SWEEP_ORDER_TOL
              and not (fm.state_dependent or fm.has_decay)):
            out[key] = ["order", r["quantity"]]   # the engine's own known shortfall (its traits say it)
    for r in summary.get("long_runs") or []:
        if r.get("finding") or r.get("status") == "diverged":
            out.setdefault((r["engine"], r["scenario"]), ["drift"])
    for r in summary.get("invariance") or []:   # a broken invariance, declared or not: one per transform
        if r.get("verdict") in ("broken", "known finding"):
            out[(r["engine"], r["scenario"], r["transform"], r["magnitude"])] = [
                "invariance", r["transform"], *str(r["magnitude"]).split()]
    return [(v, by_name[s], claim) for (v, s, *_), claim in out.items()
            if s in by_name and not v.startswith("reference:")]


def write_sweep_reproducers(out_dir, summary: dict, scenarios) -> list:
    """A reproducer of each of the sweep's findings (:func:`findings_claims`) in ``out_dir``/repro/, written
    without running them again (the sweep measured them); returns summary.json's ``reproducers`` records:
    ``{engine, scenario, claim, file}`` (``file`` relative to ``out_dir``), or ``file`` "" and ``note``
    saying why none could be written (an engine that cannot yet, forces a script cannot hold)."""
    out_dir = Path(out_dir)
    records = []
    for variant, sc, claim in findings_claims(summary, scenarios):
        text = " ".join(claim)
        rec = {"engine": variant, "scenario": sc.name, "claim": text, "file": ""}
        try:
            r = reproducer(variant, sc, claim, run=False)
        except ReproError as exc:
            records.append({**rec, "note": str(exc)})
            continue
        name = f"repro/{file_name(variant, sc.name, text)}"
        (out_dir / "repro").mkdir(exist_ok=True)
        write_reproducer(r, out_dir / name)
        records.append({**rec, "file": name})
    return records


def file_name(variant_name: str, scenario_name: str, claim: str) -> str:
    """``mujoco_rk4__tennis_racket__order_orientation.py``: a reproducer's file name in DIR/repro/."""
    safe = re.sub(r"[^A-Za-z0-9_]+", "_", f"{variant_name}__{scenario_name}__{claim}")
    return safe.strip("_") + ".py"

