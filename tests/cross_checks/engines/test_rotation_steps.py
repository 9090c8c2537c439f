"""Which reference scheme each engine's step IS (docs/engine_conventions.md, "Which reference scheme each
engine steps"): from states along a tumble near the intermediate axis (tumbling_box, where the gyroscopic
term is large and every scheme's step differs), one step of the engine against one step of every reference
variant. An engine equals a scheme when the whole state agrees within 1000 roundings of its own precision (ε
× its rounding factor: float64 steps agree to 1e-14, float32 ones to 1e-6 — 1e-5 with TGS's factor 4) and
every other scheme (ties of identical arithmetic aside, listed) is at least 10× farther; an engine that fits
none is pinned as such, with its distance to the nearest."""
from __future__ import annotations

import numpy as np
import pytest

from cross_checks.analysis.expectations import machine_epsilon
from cross_checks.core.quantities import state_errors
from cross_checks.engines import available_variants, get_adapter, resolve
from cross_checks.scenario import load_scenario
from reference_sim.integrators import VARIANTS
from tests.helpers.sweeps import COMPILED_ENGINES

#: A scheme and the reference variants whose steps are the same arithmetic on the catalog (Bullet's explicit
#: clamp never acts there; Bullet's body and world implicit steps are one step seen in two frames).
TIES = {"expmap_gyro": {"explicit_gyro_clamped"}, "implicit_gyro_body": {"implicit_gyro_world"},
        "implicit_gyro_world": {"implicit_gyro_body"}}
#: engine variant -> the reference scheme its step equals (None: none does; the nearest is not it).
IS = {
    "mujoco:euler": "expmap_gyro", "mujoco:implicit": "implicit_gyro_body",
    "mujoco:implicitfast": "implicit_gyro_body", "mujoco:discrete": "implicit_gyro_body",
    "mujoco:rk4": None,   # RK4 on q through the exponential map: 1.6e-8 from reference:rk4's whole-state RK4
    "pybullet:multibody": "expmap_gyro", "pybullet:maximal": "implicit_gyro_world",
    "drake:semi_explicit_euler": "course_gyro", "drake:runge_kutta2": None, "drake:runge_kutta3": None,
    "drake:implicit_euler": None, "dart:semi_implicit_euler": "expmap_gyro",
    "jaxsim:semi_implicit_euler": None, "jaxsim:rk4": None,
    "brax:generalized": "expmap_gyro", "brax:spring": "course", "brax:positional": None,
    "mjx:euler": "expmap_gyro", "mjx:implicitfast": "expmap_gyro", "mjx:rk4": None,
    "rapier:symplectic_euler": "jolt_gyro", "rapier:symplectic_euler_no_gyro": "course",
    "physx:tgs": "jolt_gyro", "physx:pgs": "jolt_gyro",
    "mujoco_warp:euler": "expmap_gyro", "mujoco_warp:implicit": "implicit_gyro_body",
    # in float32 MuJoCo's RK4 cannot be told from the whole-state RK4 (1.6e-8 apart: below float32)
    "mujoco_warp:rk4": "rk4",
    "mujoco_warp:implicitfast": "implicit_gyro_body", "mujoco_warp:discrete": "implicit_gyro_body",
}
DT_S = 0.01


@pytest.fixture(scope="module")
def steps():
    sc = load_scenario("tumbling_box")
    ref = get_adapter("reference")
    y0 = ref.simulate(sc, "rk4", 0.001, 3000).y[::500]          # 7 states over 3 s of the tumble
    return sc, y0, {c: ref.one_step(sc, c, DT_S, y0) for c in VARIANTS}


def _distances(steps, variant):
    sc, y0, refs = steps
    engine, name = variant.split(":")
    y1 = get_adapter(engine).one_step(sc, name, DT_S, y0)
    out = {}
    for c, yr in refs.items():
        err = state_errors(yr, y1)
        out[c] = max(float(np.max(err[q])) for q in err)
    return out


def _params():
    have = set(available_variants())
    return [pytest.param(v, marks=[pytest.mark.slow] if v.split(":")[0] in COMPILED_ENGINES else [])
            for v in IS if v in have]


@pytest.mark.parametrize("variant", _params())
def test_each_engines_step_is_the_reference_scheme_it_is_said_to_be(steps, variant):
    d = _distances(steps, variant)
    near = sorted(d, key=d.get)
    equal = 1000.0 * machine_epsilon(resolve(variant))
    scheme = IS[variant]
    if scheme is None:
        assert d[near[0]] > equal, (variant, near[0], d[near[0]])
        return
    assert near[0] in {scheme} | TIES.get(scheme, set()), (variant, [(c, d[c]) for c in near[:3]])
    assert d[scheme] <= equal, (variant, scheme, d[scheme])
    others = [c for c in near if c not in {scheme} | TIES.get(scheme, set())]
    assert d[others[0]] >= 10.0 * d[scheme], (variant, others[0], d[others[0]], d[scheme])


def test_every_shipped_engine_variant_is_identified_or_said_to_fit_none():
    shipped = {v for v in available_variants() if v.split(":")[0] not in ("reference", "genesis", "newton")}
    assert shipped <= set(IS), sorted(shipped - set(IS))
