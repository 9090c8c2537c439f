"""The adapters' plain-float per-step code (cross_checks.engines.step_floats and the loops built on it) gives
the numbers of the NumPy formulas it stands for, bit for bit: the same trajectories as the straightforward
NumPy loops written out here (start-of-step forces from ``forces.harness_force_torque``, states converted by
the adapters' array functions), on fuzz-drawn cases of every force kind with full inertia tensors."""
import numpy as np
import pytest

from cross_checks.engines import base, forces
from cross_checks.engines.step_floats import bad_floats, harness_fn
from cross_checks.engines.worlds.pybullet import qmul as quat_mul_floats
from cross_checks.fuzz import generate
from cross_checks.fuzz.pipeline import scenario_of
from reference_sim.quaternion import quat_mul
from reference_sim.simulate import BLOWUP_LIMIT, bad_rows


def _cases(n=12, seed=47):
    scs = [scenario_of(generate.draw(seed, i).spec(0.004 * (1 + i % 3), 8)) for i in range(n)]
    kinds = {f for i in range(n) for f in generate.draw(seed, i).kinds["forces"]}
    assert len(kinds) >= 7 and any(not sc.problem.body.is_diagonal() for sc in scs)
    assert (any(sc.problem.forces.has_decay for sc in scs)
            and any(sc.problem.forces.state_dependent for sc in scs))
    return scs


def _states(sc, rng, k=8):
    y = sc.problem.initial_packed() + 0.3 * rng.standard_normal((k, 13))
    y[:, 6:10] *= rng.uniform(0.5, 2.0, (k, 1))   # not unit: the force kernels normalise q themselves
    return y


def test_the_pybullet_worlds_quaternion_product_is_numpys_bit_for_bit():
    rng = np.random.default_rng(0)
    a = rng.standard_normal((20000, 4)) * 10.0 ** rng.integers(-6, 6, (20000, 4))
    b = rng.standard_normal((20000, 4)) * 10.0 ** rng.integers(-6, 6, (20000, 4))
    a[::7, 1] = 0.0
    b[::5, 2] = -0.0
    want = quat_mul(a, b)
    got = np.array([quat_mul_floats(p.tolist(), q.tolist()) for p, q in zip(a, b)])
    assert np.array_equal(np.signbit(got), np.signbit(want)) and np.array_equal(got, want)


def test_one_state_is_bad_exactly_when_bad_rows_says_so():
    rng = np.random.default_rng(1)
    y = rng.standard_normal((400, 13))
    y[1::8, 3] = np.inf
    y[2::8, 5] = -np.inf
    y[3::8, 7] = np.nan
    y[4::8, 0] = 2.0 * BLOWUP_LIMIT
    y[5::8, 12] = -2.0 * BLOWUP_LIMIT
    y[6::8, 2] = BLOWUP_LIMIT
    y[7::8, [1, 2]] = [np.inf, -np.inf]
    assert [bad_floats(row) for row in y.tolist()] == bad_rows(y).tolist()


def test_harness_is_the_base_harness_bit_for_bit_at_any_step():
    rng = np.random.default_rng(1)
    for sc in _cases():
        # the scenario's own step, and one where the decay factors are powers
        for h in (sc.dt_s, sc.dt_s / 3):
            f = harness_fn(sc, h)
            for y in _states(sc, rng):
                assert f(y.tolist()) == tuple(float(v) for v in forces.harness_force_torque_floats(sc, y, h))


# --- PyBullet -------------------------------------------------------------------------------------------

pe = pytest.importorskip("cross_checks.engines.pybullet_engine")


def _pybullet_numpy_loop(sc, variant, h, n):
    """The PyBullet run as the adapter's NumPy formulas give it, step by step; the torques fixed in body axes
    given to PyBullet (applyExternalTorque in LINK_FRAME, re-applied every step), scaled by γ_ω."""
    import dataclasses

    from cross_checks.engines.loop import body_torque_B, host_problem
    from tests.helpers.wrong_engines import BulletBody
    y0 = sc.problem.initial_packed()
    B = BulletBody(sc, variant, h, y0)
    B.set_state(y0)
    gv, gw = forces.decay_factors(sc, h)
    B.world.apply_body_torque((body_torque_B(sc.problem) * gw)[None])
    sc = dataclasses.replace(sc, problem=host_problem(sc.problem, True))   # the other forces
    raw = np.empty((n + 1, 13))
    raw[0] = B.read_raw()
    y = y0
    for k in range(1, n + 1):
        row = raw[k - 1]
        if k > 1:
            y = B.raw_to_packed(row)
        f, tau = forces.harness_force_torque(sc, y if sc.problem.forces.state_dependent else y0, h)
        if sc.problem.forces.has_decay:
            pe.p.resetBaseVelocity(B.b, (row[3:6] * gv).tolist(),
                                   (row[10:13] * gw).tolist(), physicsClientId=B.c)
        B.apply((f - B.weight).tolist(), tau.tolist(), row[0:3].tolist())
        pe.p.stepSimulation(physicsClientId=B.c)
        raw[k] = B.read_raw()
    return B.raw_to_packed(raw)


@pytest.mark.parametrize("variant", ["multibody", "maximal"])
def test_pybullet_runs_are_the_numpy_loop_bit_for_bit(variant):
    for sc in _cases():
        want = _pybullet_numpy_loop(sc, variant, sc.dt_s / 2, 16)
        run = pe.simulate(sc, variant, sc.dt_s / 2, 16)
        assert run.diverged_at_s is None and np.array_equal(run.y, want), sc.name


# --- MuJoCo ---------------------------------------------------------------------------------------------

me = pytest.importorskip("cross_checks.engines.mujoco_engine")


def _mujoco_numpy_loop(sc, variant, h, n):
    """The MuJoCo run as the adapter's NumPy formulas give it: forces from the start-of-step state (or at
    every RK4 stage through the control callback), the decay applied to qvel before the step; the torques
    fixed in body axes in qfrc_applied's rotational DOFs (body axes), scaled by γ_ω unless per stage."""
    import dataclasses

    import mujoco

    from cross_checks.engines.loop import body_torque_B, host_problem
    m = me.build_model(sc, variant, h)
    d = mujoco.MjData(m)
    xfrc = d.xfrc_applied[1]
    weight = sc.problem.body.mass_kg * np.asarray(sc.problem.forces.gravity_W, dtype=float)
    d.qpos[:], d.qvel[:] = me.to_qpos_qvel(sc.problem.initial_packed())
    per_stage = me.forces_per_stage(sc, variant)
    gv, gw = forces.decay_factors(sc, h)
    d.qfrc_applied[3:6] = body_torque_B(sc.problem) * (1.0 if per_stage else gw)
    sc = dataclasses.replace(sc, problem=host_problem(sc.problem, True))   # the other forces

    def apply(f, tau):   # the world force at the COM minus the weight (MuJoCo adds gravity), the world torque
        xfrc[0:3], xfrc[3:6] = f - weight, tau

    def control(_m, dd):
        apply(*forces.stage_force_torque(sc, me.to_packed(dd.qpos.copy(), dd.qvel.copy())))
    qpos, qvel = [d.qpos.copy()], [d.qvel.copy()]
    prev = me._set_force_callbacks(control if per_stage else None)
    try:
        for _ in range(n):
            if not per_stage:
                apply(*forces.harness_force_torque(sc, me.to_packed(d.qpos, d.qvel), h))
                d.qvel[0:3] *= gv
                d.qvel[3:6] *= gw
            mujoco.mj_step(m, d)
            qpos.append(d.qpos.copy())
            qvel.append(d.qvel.copy())
    finally:
        me._set_force_callbacks(*prev)
    return me.to_packed(np.array(qpos), np.array(qvel))


@pytest.mark.parametrize("variant", sorted(me.VARIANTS))
def test_mujoco_runs_are_the_numpy_loop_bit_for_bit(variant):
    looped = 0
    for sc in _cases():
        fm = sc.problem.forces
        if not (fm.state_dependent or fm.has_decay):
            continue   # the rollout path: tests/cross_checks/engines/test_mujoco_engine.py
        looped += 1
        want = _mujoco_numpy_loop(sc, variant, sc.dt_s / 2, 16)
        run = me.simulate(sc, variant, sc.dt_s / 2, 16)
        assert run.diverged_at_s is None and np.array_equal(run.y, want), sc.name
    assert looped >= 4


@pytest.mark.parametrize("module", [me, pe])
def test_the_host_loop_is_part_of_the_adapters_cache_key(module):
    from pathlib import Path

    import cross_checks.engines.loop as loop
    adapter = next(v for v in vars(module).values() if isinstance(v, type) and v.__module__ == module.__name__
                   and issubclass(v, base.EngineAdapter))()
    assert Path(loop.__file__) in adapter.source_files() and Path(module.__file__) in adapter.source_files()
