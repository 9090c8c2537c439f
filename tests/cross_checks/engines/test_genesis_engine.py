"""The Genesis adapter (cross_checks.engines.genesis_engine): every convention it relies on, pinned on Genesis
itself (docs/engine_conventions.md, "Genesis 1.4.5"), every default it neutralises, one step of each variant
against the hand-derived step of its scheme, its order on catalog scenarios, divergence, batching, and the
process rules (lazy import, one gs.init per process, none before a fork). Scenes are built once per process
and reused (the adapter's own cache); the first build compiles or loads Genesis's kernels."""

import functools
import math
import subprocess
import sys

import numpy as np
import pytest

from cross_checks.engines import genesis_engine as ge
from tests.helpers import tolerances as tol

try:
    ge.version()
except ImportError as exc:  # EngineNotInstalled included
    pytest.skip(f"Genesis is not installed (pip install -e '.[genesis]'): {exc}", allow_module_level=True)

from cross_checks.engines.base import EngineError, RunRequest  # noqa: E402
from cross_checks.scenario import load_scenario  # noqa: E402
from reference_sim.quaternion import geodesic_angle, matrix_from_quat, quat_exp, quat_mul  # noqa: E402
from tests.helpers.scenarios import YAW90, scenario_from_parts  # noqa: E402

Q_TILT = np.array([0.9, 0.1, 0.3, -0.2]) / np.linalg.norm([0.9, 0.1, 0.3, -0.2])
FULL_INERTIA = "mass = 2.0\ninertia = [[2.0, 0.1, 0.05], [0.1, 3.0, -0.2], [0.05, -0.2, 4.0]]"
NO_GRAVITY = "gravity = [0.0, 0.0, 0.0]"
FORCED = (
    'gravity = [0.0, 0.0, -9.81]\n[[forces.torque]]\ntorque = [0.3, -0.2, 0.5]\nframe = "world"\n'
    '[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"'
)


def _tilted(forces=NO_GRAVITY, **initial):
    """The full-tensor body at Q_TILT, 1 m, −2 m, 0.5 m from the origin, with the initial fields given (TOML).
    """
    lines = [f"orientation = {Q_TILT.tolist()}", "position = [1.0, -2.0, 0.5]"]
    lines += [f"{k} = {v}" for k, v in initial.items()]
    return scenario_from_parts(body=FULL_INERTIA, initial="\n".join(lines), forces=forces)


@pytest.fixture(scope="module")
def tilted():
    """A tumbling full-tensor body under gravity, a world force and a world torque, and its one scene (Δt =
    0.01 s)."""
    sc = _tilted(forces=FORCED, velocity="[0.3, -0.1, 0.2]", angular_velocity="[0.4, 1.5, -0.7]")
    return sc, ge.body(sc, "euler", 0.01)


def _world_inertia(sc, q):
    R = matrix_from_quat(q)
    return R @ sc.problem.body.inertia_B @ R.T


def test_version_is_the_pinned_release():
    assert ge.version() == "1.4.5"


def test_importing_the_adapter_or_asking_its_version_imports_neither_genesis_nor_torch():
    # the registry imports every adapter at CLI start and calls version(); the sweep forks after that
    code = (
        "import sys; from cross_checks.engines import all_variants, genesis_engine as ge; ge.version(); "
        "all_variants(); print('genesis' in sys.modules, 'torch' in sys.modules, 'quadrants' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False", "False"]


def test_genesis_is_initialised_once_per_process_on_the_cpu_in_float64(tilted):
    gs = ge.genesis()
    assert gs is ge.genesis() and gs._initialized
    assert gs.backend == gs.cpu and gs.np_float is np.float64 and gs.tc_float.is_floating_point
    with pytest.raises(Exception, match="already initialized"):  # gs.init is process-global, once
        gs.init(backend=gs.cpu, precision="64")


def test_a_genesis_someone_else_initialised_is_taken_when_it_is_cpu_float64(monkeypatch, tilted):
    gs = ge.genesis()
    monkeypatch.setitem(ge._STATE, "gs", None)          # as if the user's script had called gs.init first
    assert ge.genesis() is gs
    monkeypatch.setitem(ge._STATE, "gs", None)
    monkeypatch.setattr(gs, "np_float", np.float32)     # ... and with single precision: refused, said why
    with pytest.raises(EngineError, match="rbcheck needs gs.init"):
        ge.genesis()
    monkeypatch.setattr(gs, "np_float", np.float64)     # ... or without zero-copy (the world's views need it)
    monkeypatch.setattr(gs, "use_zerocopy", False)
    with pytest.raises(EngineError, match=r"zero-copy False; rbcheck needs .* and zero-copy"):
        ge.genesis()


def test_a_genesis_initialised_before_a_fork_is_refused(monkeypatch, tilted):
    monkeypatch.setitem(ge._STATE, "pid", -1)
    with pytest.raises(EngineError, match="initialised in process -1 before this process was forked"):
        ge.genesis()


def test_the_kernel_cache_is_rbchecks_and_build_times_are_recorded(tilted, monkeypatch, tmp_path):
    import os

    assert (
        os.environ["QD_OFFLINE_CACHE_FILE_PATH"].startswith(str(ge.kernel_cache_dir()))
        or "QD_OFFLINE_CACHE_FILE_PATH" in os.environ
    )  # an environment that set it keeps it
    monkeypatch.setenv("RBCHECK_KERNEL_CACHE_DIR", str(tmp_path))
    assert ge.kernel_cache_dir() == tmp_path / "genesis"
    monkeypatch.delenv("RBCHECK_KERNEL_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert ge.kernel_cache_dir() == tmp_path / "rbcheck" / "kernels" / "genesis"
    assert ge.BUILD_SECONDS and all(v in ge.VARIANTS and n >= 0 and s > 0.0 for v, n, s in ge.BUILD_SECONDS)


# --- defaults ----------------------------------------------------------------------------------------------


def test_genesis_s_own_defaults_that_the_adapter_overrides(tilted):
    gs = ge.genesis()
    rigid, sim = gs.options.RigidOptions(), gs.options.SimOptions()
    assert rigid.integrator == gs.integrator.approximate_implicitfast
    assert rigid.enable_collision and rigid.enable_joint_limit and not rigid.use_hibernation
    assert not rigid.disable_constraint and sim.substeps == 1
    morph = gs.morphs.MJCF(file=ge.mjcf_text(tilted[0]))
    assert morph.default_armature == 0.1 and morph.align is None and not morph.exclude_ground_plane


def test_unneutralised_genesis_moves_the_body_frame_and_gives_hinges_armature(tilted):
    # Genesis's defaults on the adapter's XML plus a hinged body: the free body's frame moves onto its
    # principal axes (align), the hinge gets the default armature 0.1, the free joint none (1.4.5 gives it to
    # revolute and prismatic joints only: the adapter's default_armature=0 is then belt and braces, pinned
    # here)
    gs = ge.genesis()
    xml = ge.mjcf_text(tilted[0], 0.01).replace(
        "</worldbody>",
        '<body name="arm" pos="0 0 3"><joint type="hinge" axis="0 0 1"/>'
        '<inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/></body></worldbody>',
    )
    scene = gs.Scene(sim_options=gs.options.SimOptions(dt=0.01), show_viewer=False)
    ent = scene.add_entity(gs.morphs.MJCF(file=xml))
    scene.build()
    try:
        np.testing.assert_array_equal(ent.get_dofs_armature().numpy(), np.r_[np.zeros(6), 0.1])
        q0 = ent.get_qpos().numpy()[3:7]
        assert geodesic_angle(q0, np.array([1.0, 0.0, 0.0, 0.0])) > 0.1  # the frame is no longer the body's
    finally:
        scene.destroy()


def test_a_scene_has_the_scenarios_step_gravity_and_neutral_settings():
    sc = scenario_from_parts(body=FULL_INERTIA, forces="gravity = [1.0, -2.0, 0.5]")
    B = ge.body(sc, "implicitfast", 0.004)
    gs, s = B.gs, B.solver
    assert B.scene.sim.dt == 0.004 and B.scene.sim.substeps == 1
    np.testing.assert_array_equal(np.asarray(s.get_gravity()).reshape(3), [1.0, -2.0, 0.5])
    opts = s._options
    assert opts.integrator == gs.integrator.implicitfast and not opts.enable_collision
    assert not opts.enable_joint_limit and not opts.use_hibernation and opts.disable_constraint
    for name, value in ge.NEUTRAL_DOFS:
        np.testing.assert_array_equal(getattr(B.entity, f"get_dofs_{name}")().numpy(), np.full(6, value))
    assert s.n_geoms == 0 and s.n_links == 1 and len(B.scene.entities) == 1  # no ground, nothing to touch
    lo, hi = B.entity.get_dofs_limit()
    assert np.all(np.isinf(lo.numpy())) and np.all(np.isinf(hi.numpy()))


def test_the_inertia_is_the_scenarios_full_tensor_in_body_axes_about_the_com(tilted):
    sc, B = tilted
    B.set_state(sc.problem.initial_packed())
    M = B.solver.get_mass_mat().numpy()
    # DOFs [v_W, ω_B]: M = diag(m 1, I_B) at any pose (body axes), no armature
    np.testing.assert_allclose(M[0:3, 0:3], 2.0 * np.eye(3), rtol=0, atol=tol.GENESIS_MASS_MATRIX)
    np.testing.assert_allclose(M[3:6, 3:6], sc.problem.body.inertia_B, rtol=0, atol=tol.GENESIS_MASS_MATRIX)
    np.testing.assert_allclose(M[0:3, 3:6], np.zeros((3, 3)), rtol=0, atol=tol.GENESIS_MASS_MATRIX)
    np.testing.assert_allclose(
        B.entity.get_links_pos().numpy().reshape(3), [1.0, -2.0, 0.5], rtol=0, atol=tol.GENESIS_ROUND_TRIP
    )


# --- conventions -------------------------------------------------------------------------------------------


def test_qpos_is_position_then_the_quaternion_w_first(tilted):
    sc = scenario_from_parts(body=FULL_INERTIA, initial=YAW90 + "\nposition = [1.0, 2.0, 3.0]")
    B = ge.body(sc, "euler", 0.01)
    B.set_state(sc.problem.initial_packed())
    qpos = B.read()[:, 0:7]
    np.testing.assert_allclose(
        qpos[0],
        [1.0, 2.0, 3.0, math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)],
        rtol=0,
        atol=tol.GENESIS_ROUND_TRIP,
    )
    np.testing.assert_allclose(B.entity.get_quat().numpy(), qpos[0, 3:7], rtol=0, atol=tol.GENESIS_ROUND_TRIP)


def test_dof_velocity_is_world_linear_then_body_angular_and_get_ang_is_world(tilted):
    sc, B = tilted
    w, v = np.array([0.4, 1.5, -0.7]), np.array([0.3, -0.1, 0.2])
    B.set_state(np.r_[1.0, -2.0, 0.5, v, Q_TILT, w])
    R = matrix_from_quat(Q_TILT)
    np.testing.assert_allclose(
        B.entity.get_dofs_velocity().numpy(), np.r_[v, R.T @ w], rtol=0, atol=tol.GENESIS_ROUND_TRIP
    )
    np.testing.assert_allclose(B.entity.get_ang().numpy(), w, rtol=0, atol=tol.GENESIS_ROUND_TRIP)
    np.testing.assert_allclose(B.entity.get_vel().numpy(), v, rtol=0, atol=tol.GENESIS_ROUND_TRIP)
    qpos, vel = B.read()[:, 0:7], B.read()[:, 7:13]  # the zero-copy read is the getters' numbers
    np.testing.assert_array_equal(qpos[0], B.entity.get_qpos().numpy())
    np.testing.assert_array_equal(vel[0], B.entity.get_dofs_velocity().numpy())
    np.testing.assert_allclose(
        ge.to_packed(qpos, vel)[0], np.r_[1.0, -2.0, 0.5, v, Q_TILT, w], rtol=0, atol=tol.GENESIS_ROUND_TRIP
    )


@pytest.mark.parametrize("variant", list(ge.VARIANTS))
def test_a_yawed_body_spinning_about_body_x_turns_about_world_y(variant):
    sc = scenario_from_parts(
        initial=YAW90 + "\nangular_velocity_body = [2.0, 0.0, 0.0]", dt=0.01, duration=0.5
    )
    run = ge.simulate(sc, variant, 0.01, 50)
    np.testing.assert_allclose(
        run.y[:, 10:13], np.tile([0.0, 2.0, 0.0], (51, 1)), rtol=0, atol=tol.ADAPTER_SPIN_100_STEPS
    )
    expected = quat_mul(quat_exp(np.outer(run.t_s, [0.0, 2.0, 0.0])), run.y[0, 6:10])
    assert np.max(geodesic_angle(expected, run.y[:, 6:10])) < tol.ADAPTER_SPIN_100_STEPS


def test_a_negative_w_quaternion_is_kept_as_given():
    # Genesis never flips the quaternion's sign: q1 = q0 ⊗ exp(Δt ω) stays on q0's side
    sc = scenario_from_parts(
        body=FULL_INERTIA, initial=f"orientation = {(-Q_TILT).tolist()}\nangular_velocity = [0.0, 0.0, 3.0]"
    )
    run = ge.simulate(sc, "euler", 0.01, 3)
    np.testing.assert_array_equal(run.y[0], sc.problem.initial_packed())
    assert np.all(run.y[:, 6] < 0)


# --- forces ------------------------------------------------------------------------------------------------


def _api_wrench(B, f, tau):
    """Genesis's own API for what the adapter's apply writes: a world force at the COM, a world torque."""
    f, tau = np.asarray(f, dtype=float).reshape(B.n, 3), np.asarray(tau, dtype=float).reshape(B.n, 3)
    if B.n_envs:
        f, tau = f[:, None], tau[:, None]
    B.solver.apply_links_external_wrench(force=f, torque=tau, links_idx=[B.link],
                                         ref=B.gs.link_ref_frame.link_COM, local=False)


def _wrench_of_one_step(B, sc, f, tau, fast=False):
    """The force (N) and torque about the COM (N m) one step from rest exerts: f = m Δv/Δt, τ = I_W Δω_W/Δt.
    """
    B.set_state(np.r_[1.0, -2.0, 0.5, np.zeros(3), Q_TILT, np.zeros(3)])
    (B.apply if fast else functools.partial(_api_wrench, B))(np.array([f]), np.array([tau]))
    B.step()
    assert not B.warnings
    y = B.packed(B.read())[0]
    h = B.dt_s
    return 2.0 * y[3:6] / h, _world_inertia(sc, Q_TILT) @ y[10:13] / h


def test_the_wrench_is_a_world_force_at_the_com_and_a_world_torque_cleared_after_each_step():
    sc = _tilted()
    B = ge.body(sc, "euler", 1e-3)
    F, T = np.array([1.0, 2.0, 3.0]), np.array([0.5, -0.3, 0.2])
    f, tau = _wrench_of_one_step(B, sc, F, T)
    np.testing.assert_allclose(f, F, rtol=0, atol=tol.GENESIS_WRENCH)
    np.testing.assert_allclose(tau, T, rtol=0, atol=tol.GENESIS_WRENCH)
    v1 = B.read()[:, 7:13].copy()
    B.step()  # the next step has no wrench: v unchanged
    assert not B.warnings
    np.testing.assert_array_equal(B.read()[0, 7:10], v1[0, 0:3])
    np.testing.assert_array_equal(
        B.solver.dyn_state.links.cfrc_applied_vel.to_numpy()[B.link], np.zeros((1, 3))
    )


def test_the_fast_wrench_write_is_the_apis_step_bit_for_bit(tilted):
    sc, B = tilted
    y0 = sc.problem.initial_packed()
    out = []
    for fast in (False, True):
        B.set_state(y0)
        (B.apply if fast else functools.partial(_api_wrench, B))(np.array([[1.0, 2.0, 3.0]]),
                                                                 np.array([[0.5, -0.3, 0.2]]))
        B.step()
        out.append(B.read())
    np.testing.assert_array_equal(out[0], out[1])


def test_a_velocity_set_without_the_forward_pass_gives_the_same_step(tilted):
    sc, B = tilted
    y0 = sc.problem.initial_packed()
    out = []
    for skip in (False, True):
        B.set_state(y0)
        B.step()
        vel = B.read()[:, 7:13] * 0.9
        B.entity.set_dofs_velocity(vel[0], skip_forward=skip)
        B.step()
        out.append(B.read())
    np.testing.assert_array_equal(out[0], out[1])


def test_state_dependent_forces_reach_genesis_as_the_force_models_wrench():
    sc = _tilted(
        forces='[[forces.point]]\nforce = [0.4, -1.0, 2.0]\npoint = [0.1, 0.2, -0.3]\nframe = "body"\n'
        '[[forces.spring]]\nanchor = [0.0, 0.0, 1.0]\nattach = [0.2, 0.0, 0.1]\nstiffness = 5.0',
        angular_velocity="[0.4, 1.5, -0.7]",
        velocity="[0.3, -0.1, 0.2]",
    )
    y0 = sc.problem.initial_packed()
    f, tau = sc.problem.forces.force_torque(sc.problem.body, y0[0:3], y0[3:6], y0[6:10])
    y1 = ge.one_step(sc, "euler", 1e-3, y0[None])[0]
    I_W, w = _world_inertia(sc, Q_TILT), y0[10:13]
    np.testing.assert_allclose(
        y1[3:6], y0[3:6] + 1e-3 * np.asarray(f) / 2.0, rtol=0, atol=tol.GENESIS_HAND_STEP
    )
    np.testing.assert_allclose(
        y1[10:13],
        w + 1e-3 * np.linalg.solve(I_W, np.asarray(tau) - np.cross(w, I_W @ w)),
        rtol=0,
        atol=tol.GENESIS_HAND_STEP,
    )


def test_decay_is_applied_before_the_step_with_that_steps_force_scaled():
    sc = scenario_from_parts(
        body="mass = 2.0\ninertia = [0.5, 0.5, 0.5]",
        initial="velocity = [1.0, -2.0, 0.5]\nangular_velocity = [0.3, 0.0, 3.0]",
        forces='gravity = [0.0, 0.0, -9.81]\nvelocity_decay = 0.99\nangular_velocity_decay = 0.95\n'
        '[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"\n'
        '[[forces.torque]]\ntorque = [0.1, 0.2, -0.3]\nframe = "world"',
        dt=0.01,
    )
    # ω compared in body axes: the midpoint variants turn the attitude by ω̄, not ω1, so ω1 in world axes
    # moves
    y0 = sc.problem.initial_packed()
    for variant in ge.VARIANTS:
        y1 = ge.one_step(sc, variant, 0.01, y0[None])[0]
        np.testing.assert_allclose(
            y1[3:6],
            0.99 * (y0[3:6] + 0.01 * (np.array([0.5, 1.0, 1.5]) + [0.0, 0.0, -9.81])),
            rtol=0,
            atol=tol.GENESIS_HAND_STEP,
        )
        R0, R1 = matrix_from_quat(y0[6:10]), matrix_from_quat(y1[6:10])
        np.testing.assert_allclose(
            R1.T @ y1[10:13],
            0.95 * R0.T @ (y0[10:13] + 0.01 * np.array([0.2, 0.4, -0.6])),
            rtol=0,
            atol=tol.GENESIS_HAND_STEP,
        )
        run = ge.simulate(sc, variant, 0.01, 3)  # the free run does the same
        np.testing.assert_allclose(run.y[1], y1, rtol=0, atol=tol.GENESIS_ROUND_TRIP)


# --- the step of each variant --------------------------------------------------------------------------


def test_euler_is_the_hand_derived_semi_implicit_euler_step(tilted):
    sc, _ = tilted
    h, y0 = 0.01, sc.problem.initial_packed()
    y1 = ge.one_step(sc, "euler", h, y0[None])[0]
    I_W, w = _world_inertia(sc, Q_TILT), y0[10:13]
    w1 = w + h * np.linalg.solve(I_W, np.array([0.3, -0.2, 0.5]) - np.cross(w, I_W @ w))
    v1 = y0[3:6] + h * (np.array([1.0, 2.0, 3.0]) / 2.0 + [0.0, 0.0, -9.81])
    np.testing.assert_allclose(y1[10:13], w1, rtol=0, atol=tol.GENESIS_HAND_STEP)
    np.testing.assert_allclose(y1[3:6], v1, rtol=0, atol=tol.GENESIS_HAND_STEP)
    np.testing.assert_allclose(y1[0:3], y0[0:3] + h * v1, rtol=0, atol=tol.GENESIS_HAND_STEP)
    assert geodesic_angle(quat_mul(quat_exp(h * w1), Q_TILT), y1[6:10]) < tol.GENESIS_HAND_STEP


@pytest.mark.parametrize("variant", ["implicitfast", "approximate_implicitfast"])
def test_implicit_variants_take_the_implicit_midpoint_rotation_and_the_semi_implicit_translation(
    tilted, variant
):
    # func_midpoint_free_body: I_B (ω1 − ω0)/h = τ_B − ω̄ × I_B ω̄ (body axes), ω̄ = (ω0 + ω1)/2; q1 = q0 ⊗
    # exp(h ω̄_B); the COM at the joint origin keeps v1 = v0 + h a, x1 = x0 + h v1
    sc, _ = tilted
    h, y0 = 0.01, sc.problem.initial_packed()
    y1 = ge.one_step(sc, variant, h, y0[None])[0]
    R0 = matrix_from_quat(Q_TILT)
    I_B = sc.problem.body.inertia_B
    wb0, wb1 = R0.T @ y0[10:13], matrix_from_quat(y1[6:10]).T @ y1[10:13]
    wbar = 0.5 * (wb0 + wb1)
    residual = I_B @ (wb1 - wb0) / h - (R0.T @ np.array([0.3, -0.2, 0.5]) - np.cross(wbar, I_B @ wbar))
    assert np.max(np.abs(residual)) < tol.GENESIS_MIDPOINT_RESIDUAL
    assert geodesic_angle(quat_mul(Q_TILT, quat_exp(h * wbar)), y1[6:10]) < tol.GENESIS_HAND_STEP
    v1 = y0[3:6] + h * (np.array([1.0, 2.0, 3.0]) / 2.0 + [0.0, 0.0, -9.81])
    np.testing.assert_allclose(y1[3:6], v1, rtol=0, atol=tol.GENESIS_HAND_STEP)
    np.testing.assert_allclose(y1[0:3], y0[0:3] + h * v1, rtol=0, atol=tol.GENESIS_HAND_STEP)
    # torque-free: the midpoint keeps the kinetic energy and |L|² of the tumble (to its Newton tolerance)
    sc0 = _tilted(angular_velocity="[0.4, 1.5, -0.7]")
    run = ge.simulate(sc0, variant, 0.01, 200)
    wb = np.einsum("nji,nj->ni", matrix_from_quat(run.y[:, 6:10]), run.y[:, 10:13])
    E = 0.5 * np.einsum("ni,ij,nj->n", wb, I_B, wb)
    assert np.max(np.abs(E / E[0] - 1.0)) < tol.GENESIS_MIDPOINT_ENERGY_REL


def test_the_two_implicit_variants_are_the_same_step_on_a_free_body(tilted):
    sc, _ = tilted
    a = ge.simulate(sc, "implicitfast", 0.01, 100)
    b = ge.simulate(sc, "approximate_implicitfast", 0.01, 100)
    np.testing.assert_array_equal(a.y, b.y)


def test_euler_is_mujoco_euler_to_round_off():
    from cross_checks.engines import mujoco_engine as me

    sc = load_scenario("applied_torque")
    a, b = ge.simulate(sc, "euler", 0.01, 200), me.simulate(sc, "euler", 0.01, 200)
    assert np.max(np.abs(a.y - b.y)) < tol.GENESIS_SAME_AS_MUJOCO_EULER


def test_projectile_is_the_semi_implicit_closed_form():
    sc = load_scenario("projectile")
    n, h = 100, 0.01
    for variant in ge.VARIANTS:
        run = ge.simulate(sc, variant, h, n)
        p = sc.problem
        k = np.arange(n + 1)[:, None]
        exact = (
            p.initial.x_W + k * h * p.initial.v_W + np.asarray(p.forces.gravity_W) * h * h * k * (k + 1) / 2
        )
        np.testing.assert_allclose(run.y[:, 0:3], exact, rtol=0, atol=tol.AGREE_PROJECTILE)


# --- runs ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["spring_pendulum", "velocity_decay", "applied_torque"])
def test_one_step_replays_the_run(name):
    sc = load_scenario(name)
    for variant in ("euler", "implicitfast"):
        run = ge.simulate(sc, variant, 0.01, 20)
        again = ge.one_step(sc, variant, 0.01, run.y[:-1])
        assert np.max(np.abs(again - run.y[1:]) / np.maximum(1.0, np.abs(run.y[1:]))) < tol.GENESIS_REPLAY_REL


def test_simulate_many_is_simulate_and_batches_the_runs_that_share_a_scene():
    sc, other = load_scenario("spring_pendulum"), load_scenario("velocity_decay")
    reqs = [
        RunRequest(sc, 0.01, 30),
        RunRequest(sc, 0.01, 30),
        RunRequest(other, 0.02, 10),
        RunRequest(sc, 0.02, 15),
    ]
    runs = ge.GenesisAdapter().simulate_many("euler", reqs)
    for r, run in zip(reqs, runs):
        np.testing.assert_array_equal(run.y, ge.simulate(r.scenario, "euler", r.dt_s, r.n_steps).y)
    assert any(n == 2 for v, n, _ in ge.BUILD_SECONDS if v == "euler")  # the two alike ran as 2 environments


def test_a_blow_up_is_reported_as_divergence_with_the_rows_before_it():
    # k/m = 1e6: semi-implicit Euler is unstable for ωΔt > 2; here ωΔt = 10
    sc = scenario_from_parts(
        initial="position = [0.1, 0.0, 0.0]",
        forces="[[forces.spring]]\nanchor = [0.0, 0.0, 0.0]\nattach = [0.0, 0.0, 0.0]\n"
        "stiffness = 1e6\nrest_length = 0.0",
        dt=0.01,
        duration=1.0,
    )
    run = ge.simulate(sc, "euler", 0.01, 100)
    assert run.diverged_at_s is not None and 0.0 < run.diverged_at_s < 0.2
    assert run.message.startswith(f"diverged at t = {run.diverged_at_s:.6g} s (")
    assert len(run.t_s) == round(run.diverged_at_s / 0.01) and np.all(np.abs(run.y) <= 1e8)


def test_an_inertia_the_compiler_refuses_is_an_engine_error_with_its_words():
    from types import SimpleNamespace

    sc = scenario_from_parts()
    bad = SimpleNamespace(
        name="triangle",
        problem=SimpleNamespace(  # A + B < C: MuJoCo's compiler refuses
            body=SimpleNamespace(mass_kg=1.0, inertia_B=np.diag([1.0, 1.0, 5.0])), forces=sc.problem.forces
        ),
    )
    with pytest.raises(EngineError, match="Genesis 1.4.5 rejected the model"):
        ge.body(bad, "euler", 0.01)


def test_version_and_list_name_genesis():
    from cross_checks.cli.parser import _version_text
    from cross_checks.engines import all_variants

    assert "genesis 1.4.5" in _version_text()
    infos = {v.name: v for v in all_variants() if v.engine == "genesis"}
    assert set(infos) == {f"genesis:{v}" for v in ge.VARIANTS}
    assert all(i.available and i.order == 1.0 and not i.required for i in infos.values())


def _checks(variant, scenarios, tmp_path):
    """assert_engine's checks in THIS process (jobs = 1): Genesis is initialised here, and forked workers
    refuse it."""
    from cross_checks.testing import run_engine_checks

    return run_engine_checks(variant, scenarios, cache_dir=tmp_path / "cache", jobs=1)


def test_euler_is_first_order_on_catalog_scenarios(tmp_path):
    summary = _checks("genesis:euler", ["projectile", "applied_torque"], tmp_path)
    fitted = {
        (c["scenario"], c["quantity"]): c["order"]
        for c in summary["convergence"]
        if c["verdict"] == "converges"
    }
    assert fitted[("applied_torque", "orientation")] == pytest.approx(1.0, abs=tol.DRAKE_ORDER_TOL)


@pytest.mark.slow
def test_implicitfast_rotation_is_second_order_above_its_declared_first(tmp_path):
    # a torque-free full-tensor tumble (1 s, four halving steps): the midpoint rotation converges at order 2
    from tests.helpers.scenarios import scenario_toml
    f = tmp_path / "tumble.toml"
    f.write_text(scenario_toml("tumble", 1.0, 0.01, (0.02, 0.01, 0.005, 0.0025), body=FULL_INERTIA,
                               initial="angular_velocity = [0.4, 1.5, -0.7]"))
    summary = _checks("genesis:implicitfast", [str(f)], tmp_path)
    fitted = {c["quantity"]: c["order"] for c in summary["convergence"] if c["verdict"] == "converges"}
    assert fitted["orientation"] == pytest.approx(2.0, abs=tol.DRAKE_ORDER_TOL)
    assert fitted["angular_velocity"] == pytest.approx(2.0, abs=tol.DRAKE_ORDER_TOL)


@pytest.mark.slow
def test_a_real_sweep_forks_its_workers_before_genesis_is_initialised(tmp_path):
    # `rbcheck sweep --jobs 2` in a fresh process: the parent lists and versions the engine without
    # initialising it, each forked worker initialises its own Genesis
    from tests.helpers.scenarios import TINY

    f = tmp_path / "tiny.toml"
    f.write_text(TINY)
    from pathlib import Path

    rbcheck = str(Path(sys.executable).parent / "rbcheck")
    r = subprocess.run(
        [
            rbcheck,
            "sweep",
            str(f),
            "--engines",
            "genesis:euler",
            "--out",
            str(tmp_path / "out"),
            "--no-cache",
            "--jobs",
            "2",
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    import csv

    with open(tmp_path / "out" / "results.csv") as fh:
        rows = [x for x in csv.DictReader(fh) if x["engine"] == "genesis:euler"]
    assert rows and all(x["status"] == "ok" for x in rows)
