"""The jaxsim adapter (cross_checks.engines.jaxsim_engine): every convention it relies on, pinned on jaxsim
itself (docs/engine_conventions.md, "jaxsim 0.9"), every default it neutralises, one step against the
hand-derived step of each scheme, its orders on catalog scenarios, divergence, batching, compile time, and a
forked sweep."""

import dataclasses
import importlib.util
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.helpers import tolerances as tol

# never `importorskip("jaxsim")`: importing jaxsim starts JAX's threads at COLLECTION, and every test of this
# process that forks a sweep afterwards (test_byo_engines, test_external, ...) would risk a deadlock; JAX
# starts in the tests below that need it
if importlib.util.find_spec("jaxsim") is None:
    pytest.skip("jaxsim is not installed (pip install -e '.[jaxsim]')", allow_module_level=True)

from cross_checks.engines import jaxsim_engine as je  # noqa: E402
from cross_checks.engines.base import RunRequest  # noqa: E402
from cross_checks.scenario import load_scenario  # noqa: E402
from reference_sim.quaternion import geodesic_angle, matrix_from_quat, quat_mul  # noqa: E402
from tests.helpers.scenarios import FAST_SPIN, YAW90, scenario_from_parts  # noqa: E402

SIE, RK4 = "semi_implicit_euler", "rk4"
Q_TILT = np.array([0.9, 0.1, 0.3, -0.2]) / np.linalg.norm([0.9, 0.1, 0.3, -0.2])
FULL_INERTIA = "mass = 2.0\ninertia = [[2.0, 0.1, 0.05], [0.1, 3.0, -0.2], [0.05, -0.2, 4.0]]"
NO_GRAVITY = "gravity = [0.0, 0.0, 0.0]"
GRAVITY = "gravity = [0.0, 0.0, -9.81]"
WRENCH = (
    '[[forces.torque]]\ntorque = [0.3, -0.2, 0.5]\nframe = "world"\n'
    '[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"'
)


@pytest.fixture(scope="module")
def jx():
    """(jax, jax.numpy, jaxsim.api) as the adapter imports them."""
    return je.JaxsimAdapter().modules()[:3]


@pytest.fixture(scope="module")
def jsw():
    """cross_checks.engines.worlds.jaxsim (the model, step and chunk the adapter runs), JAX started."""
    return je.JaxsimAdapter().modules()[3]


def _tilted(body=FULL_INERTIA, forces=NO_GRAVITY, **initial):
    """A scenario whose body starts at Q_TILT, at (1, −2, 0.5) m (away from the origin), with the given
    fields."""
    lines = [f"orientation = {Q_TILT.tolist()}", "position = [1.0, -2.0, 0.5]"]
    lines += [f"{k} = {v}" for k, v in initial.items()]
    return scenario_from_parts(body=body, initial="\n".join(lines), forces=forces)


def _world_inertia(sc, q):
    R = matrix_from_quat(q)
    return R @ sc.problem.body.inertia_B @ R.T


def _data(jx, sc, y, variant=SIE):
    jax, jnp, js = jx
    from jaxsim import VelRepr

    return js.data.JaxSimModelData.build(
        model=je.build_model(sc, variant),
        base_position=y[0:3],
        base_quaternion=y[6:10],
        base_linear_velocity=y[3:6],
        base_angular_velocity=y[10:13],
        velocity_representation=VelRepr.Mixed,
    )


def _sie_step(sc, y0, h, f_W, tau_W):
    """jaxsim's semi-implicit Euler by hand (jaxsim/api/integrators.py): in the INERTIAL representation
    (v_in = v − ω × x), ν_in += h ν̇_in, x += h (v_in⁺ + ω⁺ × x), q += h ½ [0, ω⁺] ⊗ q normalised."""
    x0, v0, q0, w0 = y0[0:3], y0[3:6], y0[6:10], y0[10:13]
    I_W = _world_inertia(sc, q0)
    wd = np.linalg.solve(I_W, tau_W - np.cross(w0, I_W @ w0))
    a = f_W / sc.problem.body.mass_kg
    vin1 = v0 - np.cross(w0, x0) + h * (a - np.cross(wd, x0) - np.cross(w0, v0))
    w1 = w0 + h * wd
    x1 = x0 + h * (vin1 + np.cross(w1, x0))
    q1 = q0 + h * 0.5 * quat_mul(np.r_[0.0, w1], q0)
    return np.r_[x1, vin1 + np.cross(w1, x1), q1 / np.linalg.norm(q1), w1]


# --- the package, its version and process-wide effects --------------------------------------------------


def test_version_is_the_pinned_release_and_read_without_importing_jax():
    assert je.version() == "0.9.0"
    code = (
        "import sys\nfrom cross_checks.engines import all_variants, jaxsim_engine as je\n"
        "assert je.version()\n"
        "[v for v in all_variants()]\nje.JaxsimAdapter().cache_token()\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('jax', 'jaxlib', 'jaxsim')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == "[]"  # listing and cache keys never start JAX (fork safety)


def test_importing_jaxsim_leaves_the_processs_warnings_as_they_were():
    """``import jaxsim`` sets a filter "once" for every warning and a ``warnings.showwarning`` that prints any
    site-packages module's warning to stdout in its own colours (jaxsim/logging.py: its root is site-packages
    itself); the adapter imports it with the process's filters and ``showwarning`` restored after. Checked in
    a fresh interpreter, where the import runs jaxsim's module code."""
    code = (
        "import warnings\nfrom cross_checks.engines import jaxsim_engine as je\n"
        "show, filters = warnings.showwarning, list(warnings.filters)\n"
        "je._ENGINE.modules()\n"
        "import jaxsim.logging\n"   # imported: the module that replaces them ran
        "print(warnings.showwarning is show, warnings.filters == filters)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip().splitlines()[-1] == "True True"


def test_float64_is_on_process_wide(jx):
    jax, jnp, js = jx
    assert jax.config.jax_enable_x64 and jnp.zeros(1).dtype == jnp.float64
    sc = load_scenario("projectile")
    assert je.simulate(sc, SIE, 0.01, 3).y.dtype == np.float64


def test_rk4fast_is_not_offered_it_fails_on_a_body_without_collision_points(jx, jsw):
    jax, jnp, js = jx
    assert set(jsw.INTEGRATORS.values()) == {"SemiImplicitEuler", "RungeKutta4"}
    model = dataclasses.replace(
        je.build_model(_tilted(), RK4), integrator=js.model.IntegratorType.RungeKutta4Fast
    )
    with pytest.raises(UnboundLocalError, match="W_f_L_terrain"):
        js.model.step(model, js.data.JaxSimModelData.build(model=model))


# --- conventions -------------------------------------------------------------------------------------


def test_quaternion_order_is_w_first(jx):
    # (w, x, y, z) = (√½, 0, 0, √½) is 90° about z: body x along world y
    sc = scenario_from_parts(initial=YAW90)
    d = _data(jx, sc, sc.problem.initial_packed())
    R = np.asarray(d.base_transform)[0:3, 0:3]
    np.testing.assert_allclose(R @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], rtol=0, atol=tol.JAXSIM_ROUND_TRIP)
    np.testing.assert_array_equal(np.asarray(d.base_quaternion), sc.problem.initial_packed()[6:10])


def test_mixed_velocities_are_the_coms_and_omega_in_world_axes(jx):
    from jaxsim import VelRepr

    sc = _tilted()
    w, v = np.array([0.1, 0.2, 0.3]), np.array([4.0, 5.0, 6.0])
    d = _data(jx, sc, np.r_[1.0, -2.0, 0.5, v, Q_TILT, w])
    np.testing.assert_allclose(np.asarray(d.base_velocity), np.r_[v, w], rtol=0, atol=tol.JAXSIM_ROUND_TRIP)
    R = matrix_from_quat(Q_TILT)
    with d.switch_velocity_representation(VelRepr.Body):
        np.testing.assert_allclose(
            np.asarray(d.base_velocity), np.r_[R.T @ v, R.T @ w], rtol=0, atol=tol.JAXSIM_ROUND_TRIP
        )
    with d.switch_velocity_representation(VelRepr.Inertial):  # what jaxsim integrates: v − ω × x
        np.testing.assert_allclose(
            np.asarray(d.base_velocity)[0:3],
            v - np.cross(w, [1.0, -2.0, 0.5]),
            rtol=0,
            atol=tol.JAXSIM_ROUND_TRIP,
        )


def test_the_full_tensor_is_kept_about_the_com_in_link_axes(jx):
    jax, jnp, js = jx
    sc = _tilted()
    M = np.asarray(js.model.link_spatial_inertia_matrices(je.build_model(sc, SIE)))[0]
    np.testing.assert_array_equal(M[3:6, 3:6], sc.problem.body.inertia_B)
    np.testing.assert_array_equal(M[0:3, 0:3], 2.0 * np.eye(3))
    np.testing.assert_array_equal(M[0:3, 3:6], np.zeros((3, 3)))  # COM at the link origin
    # and the gyroscopic term is jaxsim's own, in the scenario's body frame: ω1 = ω0 − Δt I_W⁻¹(ω0 × I_W ω0)
    sc = _tilted(angular_velocity="[0.4, 1.5, -0.7]")
    y0 = sc.problem.initial_packed()
    y1 = je.one_step(sc, SIE, 0.01, y0[None])[0]
    I_W, w = _world_inertia(sc, Q_TILT), y0[10:13]
    np.testing.assert_allclose(
        y1[10:13], w - 0.01 * np.linalg.solve(I_W, np.cross(w, I_W @ w)), rtol=0, atol=tol.JAXSIM_HAND_STEP
    )


def test_sdf_numbers_are_the_exact_doubles(jsw):
    sdf = jsw.model_sdf(0.1 + 0.2, np.diag([1 / 3, 2.0, 3.0]))
    assert "<mass>0.30000000000000004</mass>" in sdf and "<ixx>0.3333333333333333</ixx>" in sdf
    assert "collision" not in sdf and "joint" not in sdf


# --- one step by hand ----------------------------------------------------------------------------------


def test_one_step_is_the_hand_derived_semi_implicit_euler_step_in_the_inertial_representation():
    sc = _tilted(
        forces=GRAVITY + "\n" + WRENCH, velocity="[0.3, -0.1, 0.2]", angular_velocity="[0.4, 1.5, -0.7]"
    )
    h, y0 = 0.01, sc.problem.initial_packed()
    y1 = je.one_step(sc, SIE, h, y0[None])[0]
    f = np.array([1.0, 2.0, 3.0]) + 2.0 * np.array([0.0, 0.0, -9.81])
    np.testing.assert_allclose(
        y1, _sie_step(sc, y0, h, f, np.array([0.3, -0.2, 0.5])), rtol=0, atol=tol.JAXSIM_HAND_STEP
    )
    # not the course's translation: v1 − (v0 + h f/m) = O(h) terms in ω × x and ω × v
    assert np.max(np.abs(y1[3:6] - (y0[3:6] + h * f / 2.0))) > 1e-4


def _rk4_step(sc, y0, h, f_W, tau_W):
    """jaxsim's RK4 by hand (jaxsim/api/integrators.py rk4_integration): classical RK4 on (x, q, v_in, ω)
    with the INERTIAL wrench of the start state held — the force f_W and its moment about the WORLD ORIGIN
    τ_W + x0 × f_W — each stage's quaternion normalised before its derivative (data.replace), the result's
    normalised."""
    m, x0 = sc.problem.body.mass_kg, y0[0:3]
    tau_in = tau_W + np.cross(x0, f_W)
    g = np.asarray(sc.problem.forces.gravity_W, dtype=float)

    def rhs(s):
        x, q, vin, w = s[0:3], s[3:7] / np.linalg.norm(s[3:7]), s[7:10], s[10:13]
        I_W = _world_inertia(sc, q)
        xd = vin + np.cross(w, x)
        wd = np.linalg.solve(I_W, tau_in - np.cross(x, f_W) - np.cross(w, I_W @ w))
        return np.r_[
            xd, 0.5 * quat_mul(np.r_[0.0, w], q), f_W / m + g - np.cross(wd, x) - np.cross(w, xd), wd
        ]

    s0 = np.r_[x0, y0[6:10], y0[3:6] - np.cross(y0[10:13], x0), y0[10:13]]
    k1 = rhs(s0)
    k2 = rhs(s0 + 0.5 * h * k1)
    k3 = rhs(s0 + 0.5 * h * k2)
    k4 = rhs(s0 + h * k3)
    s1 = s0 + h * (k1 + 2 * k2 + 2 * k3 + k4) / 6
    x1, q1, w1 = s1[0:3], s1[3:7] / np.linalg.norm(s1[3:7]), s1[10:13]
    return np.r_[x1, s1[7:10] + np.cross(w1, x1), q1, w1]


def test_one_rk4_step_is_classical_rk4_with_the_start_wrench_held_in_the_inertial_representation():
    # a spring (state-dependent) evaluated once, at the start; the held wrench is the inertial one, so the
    # torque about the COM at a stage is τ + (x0 − x_stage) × f: the force keeps its line of action in space
    sc = _tilted(
        forces=GRAVITY + "\n[[forces.spring]]\nanchor = [0.0, 0.0, 1.0]\nattach = [0.0, 0.0, 0.0]\n"
        "stiffness = 50.0\n" + WRENCH,
        velocity="[0.3, -0.1, 0.2]",
        angular_velocity="[0.4, 1.5, -0.7]",
    )
    h, y0 = 0.01, sc.problem.initial_packed()
    f, tau = sc.problem.forces.force_torque(sc.problem.body, y0[0:3], y0[3:6], y0[6:10])
    y1 = je.one_step(sc, RK4, h, y0[None])[0]
    weight = 2.0 * np.array([0.0, 0.0, -9.81])
    np.testing.assert_allclose(
        y1, _rk4_step(sc, y0, h, np.asarray(f) - weight, np.asarray(tau)), rtol=0, atol=tol.JAXSIM_HAND_STEP
    )


def test_rk4_with_a_constant_force_at_the_com_is_first_order_in_rotation():
    # the held inertial wrench gives a moving body the torque (x0 − x(t)) × f within a step: ∫ = −h²/2 v × f,
    # a local O(h²) error in ω — first order, although the force is constant (no scenario of the catalog has a
    # constant applied force other than gravity, which jaxsim applies as an acceleration)
    sc = scenario_from_parts(
        body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]",
        initial="velocity = [1.0, 0.0, 0.0]",
        forces='[[forces.point]]\nforce = [0.0, 2.0, 0.0]\nframe = "world"',
    )
    errs = []
    for h in (0.02, 0.01, 0.005):
        run = je.simulate(sc, RK4, h, round(1.0 / h))
        errs.append(np.max(np.abs(run.y[-1, 10:13])))  # exact: ω stays 0
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    np.testing.assert_allclose(orders, 1.0, atol=tol.JAXSIM_ORDER_TOL)
    assert errs[-1] > 1e-3


# --- gravity and forces ------------------------------------------------------------------------------


@pytest.mark.parametrize("gravity", [[0.0, 0.0, -9.81], [1.0, -2.0, 0.5]])
def test_projectile_is_the_semi_implicit_closed_form_whatever_the_gravitys_direction(gravity):
    sc = scenario_from_parts(
        initial="velocity = [1.0, 0.0, 3.0]\nposition = [1.0, -2.0, 0.5]", forces=f"gravity = {gravity}"
    )
    # jaxsim's gravity is a scalar along z: any other direction runs in a frame turned onto it
    assert je.engine_gravity(sc) == (9.81 if gravity[0] == 0.0 else -float(np.linalg.norm(gravity)))
    n, h = 100, 0.01
    run = je.simulate(sc, SIE, h, n)
    k = np.arange(n + 1)[:, None]
    exact = (
        np.array([1.0, -2.0, 0.5])
        + k * h * np.array([1.0, 0.0, 3.0])
        + np.array(gravity) * h * h * k * (k + 1) / 2
    )
    np.testing.assert_allclose(run.y[:, 0:3], exact, rtol=0, atol=tol.AGREE_PROJECTILE)
    np.testing.assert_allclose(
        run.y[:, 3:6],
        np.array([1.0, 0.0, 3.0]) + k * h * np.array(gravity),
        rtol=0,
        atol=tol.AGREE_PROJECTILE,
    )


@pytest.mark.parametrize("gravity", [[1.0, -2.0, 0.5], [0.3, 4.0, -9.0], [-9.81, 0.0, 0.0]])
def test_a_gravity_off_the_z_axis_is_turned_onto_it(gravity):
    sc = scenario_from_parts(forces=f"gravity = {gravity}")
    r = je.jaxsim_frame(sc)
    g = np.asarray(gravity)
    np.testing.assert_allclose(matrix_from_quat(r) @ g, [0.0, 0.0, -je.engine_gravity(sc)], rtol=0,
                               atol=tol.JAXSIM_ROUND_TRIP * 10.0)
    assert je.jaxsim_frame(scenario_from_parts(forces=GRAVITY)) is None   # along z: not turned at all
    y = sc.problem.initial_packed() + np.arange(13) * 0.1
    np.testing.assert_allclose(je.turned(r, je.turned(r, y), back=True), y, rtol=0,
                               atol=tol.JAXSIM_ROUND_TRIP * 10.0)


@pytest.mark.parametrize("name", ["particle_body", "spring_pendulum"])
def test_rk4_in_a_turned_world_is_the_original_turned(name):
    # jaxsim converts a link force to a wrench about the world origin at the start of a step and RK4 holds it:
    # a weight given as a link force acts at the start-of-step COM, not the moving one, a first-order error
    # (the invariance check's world rotation measured 0.166, 0.0831, 0.0416 rad/s on particle_body at Δt,
    # Δt/2, Δt/4, 1.5 rad/s on spring_pendulum). jaxsim now applies the whole gravity in a frame turned onto
    # it, so the turned world's run is the original's turned to round-off, held state-dependent forces
    # included
    from cross_checks.scenario.transforms import WorldRotation, apply, default_transforms
    t = next(t for t in default_transforms() if isinstance(t, WorldRotation))
    sc = load_scenario(name)
    n = 500
    a, b = je.simulate_many(RK4, [RunRequest(sc, sc.dt_s, n), RunRequest(apply(t, sc), sc.dt_s, n)])
    np.testing.assert_allclose(t.map_back(b.y), a.y, rtol=0, atol=tol.JAXSIM_TURNED_WORLD)


def test_world_force_acts_at_the_com_and_world_torque_about_it():
    # from rest at the origin (no gyroscopic term, no ω × x), one short step: f = m Δv/Δt, τ = I_W Δω/Δt — the
    # harness's wrench as it is, in world axes (the body is tilted)
    sc = scenario_from_parts(body=FULL_INERTIA, initial=f"orientation = {Q_TILT.tolist()}", forces=WRENCH)
    y0, h = sc.problem.initial_packed(), 1e-6
    y1 = je.one_step(sc, SIE, h, y0[None])[0]
    np.testing.assert_allclose(2.0 * (y1[3:6] - y0[3:6]) / h, [1.0, 2.0, 3.0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        _world_inertia(sc, Q_TILT) @ y1[10:13] / h, [0.3, -0.2, 0.5], rtol=0, atol=1e-9
    )


def test_state_dependent_forces_are_the_force_models_from_each_rows_state_and_nothing_stays():
    # a body-frame force off the COM and a spring off the COM: per row (three different states, one vmapped
    # call) the step is the hand step with ForceModel.force_torque of that row; no callback context
    # is left over
    sc = _tilted(
        forces='[[forces.point]]\nforce = [0.4, -1.0, 2.0]\npoint = [0.1, 0.2, -0.3]\nframe = "body"\n'
        "[[forces.spring]]\nanchor = [0.0, 0.0, 1.0]\nattach = [0.2, 0.0, 0.1]\nstiffness = 5.0",
        angular_velocity="[0.4, 1.5, -0.7]",
        velocity="[0.3, -0.1, 0.2]",
    )
    y0 = sc.problem.initial_packed()
    rows = np.array([y0, y0 + np.r_[0.5, 0.0, -0.3, np.zeros(10)], y0 + np.r_[np.zeros(10), 0.2, -0.1, 0.3]])
    out = je.one_step(sc, SIE, 1e-3, rows)
    for y, y1 in zip(rows, out):
        f, tau = sc.problem.forces.force_torque(sc.problem.body, y[0:3], y[3:6], y[6:10])
        np.testing.assert_allclose(
            y1, _sie_step(sc, y, 1e-3, np.asarray(f), np.asarray(tau)), rtol=0, atol=tol.JAXSIM_HAND_STEP
        )
    assert je._CONTEXTS == {}
    # a step without forces after them has none: jaxsim's step keeps nothing between calls
    free = _tilted(angular_velocity="[0.4, 1.5, -0.7]", velocity="[0.3, -0.1, 0.2]")
    np.testing.assert_allclose(
        je.one_step(free, SIE, 1e-3, y0[None])[0],
        _sie_step(free, y0, 1e-3, np.zeros(3), np.zeros(3)),
        rtol=0,
        atol=tol.JAXSIM_HAND_STEP,
    )


def test_decay_is_applied_before_the_step_with_that_steps_force_scaled():
    sc = scenario_from_parts(
        body="mass = 2.0\ninertia = [0.5, 0.5, 0.5]",
        initial="velocity = [1.0, -2.0, 0.5]\nangular_velocity = [0.3, 0.0, 3.0]",
        forces=GRAVITY + "\nvelocity_decay = 0.99\nangular_velocity_decay = 0.95\n"
        '[[forces.point]]\nforce = [1.0, 2.0, 3.0]\nframe = "world"\n'
        '[[forces.torque]]\ntorque = [0.1, 0.2, -0.3]\nframe = "world"',
        dt=0.01,
    )
    # the pre-step factors on v and ω, the harness's force and torque × the same factors (the weight included:
    # jaxsim adds m g, the link force carries γ_v (F + m g) − m g), then jaxsim's step
    y0 = sc.problem.initial_packed()
    y1 = je.one_step(sc, SIE, 0.01, y0[None])[0]
    y_dec = y0 * np.r_[1, 1, 1, 0.99, 0.99, 0.99, 1, 1, 1, 1, 0.95, 0.95, 0.95]
    f = 0.99 * (np.array([1.0, 2.0, 3.0]) + 2.0 * np.array([0.0, 0.0, -9.81]))
    np.testing.assert_allclose(
        y1,
        _sie_step(sc, y_dec, 0.01, f, 0.95 * np.array([0.1, 0.2, -0.3])),
        rtol=0,
        atol=tol.JAXSIM_HAND_STEP,
    )
    np.testing.assert_allclose(je.simulate(sc, SIE, 0.01, 3).y[1], y1, rtol=0, atol=tol.JAXSIM_ROUND_TRIP)


# --- defaults ----------------------------------------------------------------------------------------


def test_jaxsims_own_defaults(jx, jsw):
    jax, jnp, js = jx
    import jaxsim

    m = js.model.JaxSimModel.build_from_model_description(jsw.model_sdf(1.0, np.eye(3)), is_urdf=False)
    assert isinstance(m.contact_model, jaxsim.rbda.contacts.SoftContacts)  # a soft plane ...
    assert (
        isinstance(m.terrain, jaxsim.terrain.FlatTerrain) and float(m.terrain.height(0.0, 0.0)) == 0.0
    )  # at z = 0
    assert (
        m.gravity == -9.81
        and m.time_step == 0.001
        and m.integrator == js.model.IntegratorType.SemiImplicitEuler
    )
    assert m.actuation_params.omega_max == 100.0 and m.actuation_params.enable_friction  # joint-space only


def test_the_model_has_no_collidable_point_joint_or_constraint():
    m = je.build_model(_tilted(), SIE)
    kp = m.kin_dyn_parameters
    assert len(kp.contact_parameters.body) == 0 and m.dofs() == 0 and m.floating_base()
    assert kp.constraints is None or len(kp.constraints.frame_idxs_1) == 0


def test_no_contact_force_ever_acts_a_body_below_the_ground_moves_as_one_above():
    def run(z):
        sc = scenario_from_parts(
            initial=f"position = [0.0, 0.0, {z}]\nvelocity = [1.0, 0.0, -3.0]", forces=GRAVITY
        )
        return je.simulate(sc, SIE, 0.01, 100).y

    above, below = run(5.0), run(-5.0)
    np.testing.assert_array_equal(above[:, 3:], below[:, 3:])
    np.testing.assert_allclose(above[:, 2] - below[:, 2], 10.0, rtol=0, atol=1e-12)


def test_no_velocity_clamp_a_spin_beyond_omega_max_is_kept():
    sc = scenario_from_parts(
        body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]", initial="angular_velocity = [0.0, 150.0, 0.0]"
    )
    run = je.simulate(sc, SIE, 1e-3, 20)
    np.testing.assert_array_equal(run.y[:, 10:13], np.tile([0.0, 150.0, 0.0], (21, 1)))


def test_the_time_step_is_the_runs():
    sc = scenario_from_parts(initial="velocity = [1.0, 0.0, 0.0]")
    for h in (0.004, 0.01):
        assert je.simulate(sc, SIE, h, 1).y[1, 0] == pytest.approx(h, rel=1e-15)


# --- runs --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "variant, name",
    [
        (SIE, "tumbling_box"),
        # the state-dependent path (a callback in the compiled loop: compiled again in every process, ~20 s)
        pytest.param(SIE, "spring_pendulum", marks=pytest.mark.slow),
        pytest.param(RK4, "spring_pendulum", marks=pytest.mark.slow),
    ],
)
def test_one_step_replays_the_run_and_simulate_many_is_simulate(variant, name):
    sc = load_scenario(name)
    run = je.simulate(sc, variant, 0.01, 20)
    again = je.one_step(sc, variant, 0.01, run.y[:-1])
    assert np.max(np.abs(again - run.y[1:]) / np.maximum(1.0, np.abs(run.y[1:]))) < tol.JAXSIM_REPLAY_REL
    many = je.simulate_many(variant, [RunRequest(sc, 0.01, 20), RunRequest(sc, 0.02, 7)])
    np.testing.assert_array_equal(many[0].y, run.y)
    np.testing.assert_array_equal(many[1].y, je.simulate(sc, variant, 0.02, 7).y)


def test_runs_longer_than_a_chunk_continue_exactly(jsw):
    sc = load_scenario("tennis_racket")
    n = jsw.CHUNK + 37
    run = je.simulate(sc, SIE, 1e-3, n)
    assert run.y.shape == (n + 1, 13) and run.t_s[-1] == pytest.approx(n * 1e-3)
    again = je.one_step(sc, SIE, 1e-3, run.y[jsw.CHUNK - 2 : jsw.CHUNK + 2])
    assert np.max(np.abs(again - run.y[jsw.CHUNK - 1 : jsw.CHUNK + 3])) < tol.JAXSIM_REPLAY_REL * 10


def test_the_fast_spin_diverges_where_the_reference_of_the_same_rotation_scheme_does():
    # reference:course_gyro has jaxsim's rotation update (explicit gyroscopic term, q += Δt q̇ normalised):
    # the two agree to round-off over the first second, then the runaway amplifies round-off, and both blow up
    # within a few steps of each other (measured 8.66 s and 8.68 s)
    from reference_sim.simulate import simulate as reference_simulate

    sc = scenario_from_parts(initial=FAST_SPIN, dt=0.01, duration=10.0)
    a, b = je.simulate(sc, SIE, 0.01, 1000), reference_simulate(sc.problem, "course_gyro", 0.01, 1000)
    np.testing.assert_allclose(a.y[:101, 10:13], b.y[:101, 10:13], rtol=0, atol=tol.JAXSIM_SAME_ROTATION)
    assert a.diverged_at_s is not None and abs(a.diverged_at_s - b.diverged_at_s) < 0.05
    assert a.message == f"diverged at t = {a.diverged_at_s:.6g} s (state beyond 1e+08)"
    assert len(a.t_s) == round(a.diverged_at_s / 0.01) and np.all(np.abs(a.y) <= 1e8)


@pytest.mark.slow
def test_a_blow_up_is_reported_as_divergence_with_the_rows_before_it():
    sc = scenario_from_parts(
        initial="position = [0.1, 0.0, 0.0]",
        forces="[[forces.spring]]\nanchor = [0.0, 0.0, 0.0]\nattach = [0.0, 0.0, 0.0]\n"
        "stiffness = 1e6\nrest_length = 0.0",
        dt=0.01,
        duration=1.0,
    )
    run = je.simulate(sc, SIE, 0.01, 100)
    assert run.diverged_at_s is not None and 0.0 < run.diverged_at_s < 0.2
    assert run.message == f"diverged at t = {run.diverged_at_s:.6g} s (state beyond 1e+08)"
    assert len(run.t_s) == round(run.diverged_at_s / 0.01) and np.all(np.abs(run.y) <= 1e8)


def test_quaternions_stay_continuous_and_the_first_row_is_the_scenarios():
    sc = scenario_from_parts(
        body="mass = 1.0\ninertia = [1.0, 1.0, 1.0]",
        initial=f"orientation = {(-Q_TILT).tolist()}\nangular_velocity = [0.0, 0.0, 3.0]",
    )
    run = je.simulate(sc, SIE, 0.01, 300)
    np.testing.assert_array_equal(run.y[0], sc.problem.initial_packed())
    assert np.max(np.linalg.norm(np.diff(run.y[:, 6:10], axis=0), axis=1)) < 0.02
    # an isotropic spin about world z: ω constant, the attitude turns by |ω|Δt per step (q += Δt q̇,
    # normalised:
    # atan(|ω|Δt/2) per half angle, a phase error of (|ω|Δt)³/12 per step)
    angle = 2 * np.arctan(0.015) * np.arange(301)
    expected = np.array([quat_mul([np.cos(a / 2), 0.0, 0.0, np.sin(a / 2)], -Q_TILT) for a in angle])
    assert np.max(geodesic_angle(expected, run.y[:, 6:10])) < tol.JAXSIM_ROUND_TRIP * 1e3


def test_compile_time_is_measured_apart_and_paid_once_per_shape():
    adapter = je.JaxsimAdapter()
    je.simulate(load_scenario("projectile"), SIE, 0.01, 5)
    before = je.timings()
    assert adapter.compile_seconds == before["compile_seconds"] > 0.0 and before["compilations"] >= 1
    je.simulate(
        scenario_from_parts(body="mass = 3.0\ninertia = [1.0, 2.0, 3.0]", forces=GRAVITY), SIE, 0.002, 5
    )
    after = je.timings()
    assert after["compilations"] == before["compilations"]
    assert after["compile_seconds"] == before["compile_seconds"]
    assert after["body_steps"] == before["body_steps"] + 5 and after["step_seconds"] > before["step_seconds"]


def test_version_and_list_name_jaxsim():
    from cross_checks.cli.parser import _version_text
    from cross_checks.engines import all_variants

    assert "jaxsim 0.9.0" in _version_text()
    info = {v.name: v for v in all_variants()}
    assert info["jaxsim:semi_implicit_euler"].order == 1.0 and info["jaxsim:rk4"].order == 4.0
    assert info["jaxsim:rk4"].available and not info["jaxsim:rk4"].required
    assert je.VARIANTS["rk4"].traits.forces_held and not je.VARIANTS[SIE].traits.forces_held


# --- orders (one process: the test process has started JAX, so no forked workers here) -------------------


def _fitted(variant, scenarios, cache):
    from cross_checks.testing import run_engine_checks

    summary = run_engine_checks(variant, scenarios, jobs=1, cache_dir=cache)
    return {
        (c["scenario"], c["quantity"]): (c["order"], c["verdict"], c.get("expected_verdict"))
        for c in summary["convergence"]
    }


@pytest.mark.slow
def test_rk4_is_fourth_order_with_constant_forces_and_first_order_where_they_are_held(tmp_path):
    fitted = _fitted("jaxsim:rk4", ["particle_body", "applied_torque"], tmp_path)
    assert fitted[("particle_body", "orientation")][0] == pytest.approx(4.0, abs=tol.JAXSIM_ORDER_TOL)
    assert fitted[("applied_torque", "orientation")][0] == pytest.approx(1.0, abs=tol.JAXSIM_ORDER_TOL)
    assert fitted[("applied_torque", "angular_velocity")][0] == pytest.approx(1.0, abs=tol.JAXSIM_ORDER_TOL)


@pytest.mark.slow
def test_rk4_is_fourth_order_on_a_torque_free_tumble(tmp_path):
    fitted = _fitted("jaxsim:rk4", ["constant_spin"], tmp_path)
    assert fitted[("constant_spin", "orientation")][0] == pytest.approx(4.0, abs=tol.JAXSIM_ORDER_TOL)


@pytest.mark.slow
def test_semi_implicit_euler_is_first_order_on_catalog_scenarios(tmp_path):
    fitted = _fitted("jaxsim:semi_implicit_euler", ["applied_torque", "linear_drag"], tmp_path)
    assert fitted[("applied_torque", "orientation")][0] == pytest.approx(1.0, abs=tol.JAXSIM_ORDER_TOL)
    assert fitted[("linear_drag", "position")][0] == pytest.approx(1.0, abs=tol.JAXSIM_ORDER_TOL)


# --- a forked sweep ----------------------------------------------------------------------------------


@pytest.mark.slow
def test_a_sweep_with_forked_workers_runs_jaxsim(tmp_path):
    # the parent lists and schedules without starting JAX, each forked worker starts its own (a fork after JAX
    # is initialised can deadlock: the timeout would say so)
    env = {**os.environ, "MPLBACKEND": "Agg"}
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "cross_checks.cli",
            "sweep",
            "projectile",
            "--engines",
            "jaxsim",
            "--out",
            str(tmp_path / "r"),
            "--no-cache",
            "--jobs",
            "2",
        ],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    import json

    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert {"jaxsim:semi_implicit_euler", "jaxsim:rk4"} <= {v["name"] for v in summary["variants"]}
    assert "os.fork() was called" not in out.stderr  # JAX was never started in the forking process


def test_the_link_carries_the_mass_and_inertia_to_a_few_roundings_and_a_wrong_one_is_refused(monkeypatch):
    """jaxsim holds a mass of 1.4 kg as 1.3999999999999997 kg (found by rbcheck fuzz); a parameter off by more
    than ENGINE_MODEL_PARAMETER_REL is refused."""
    sc = scenario_from_parts(body="mass = 1.4\ninertia = [1.0, 5.0, 5.0]")
    assert np.all(np.isfinite(je.simulate(sc, SIE, 0.01, 2).y))        # built, checked and run
    _, _, js = je.JaxsimAdapter().modules()[:3]
    real = js.model.link_spatial_inertia_matrices

    def off(model):
        return real(model) * (1.0 + 1e-9)
    monkeypatch.setattr(js.model, "link_spatial_inertia_matrices", off)
    je._model.cache_clear()
    with pytest.raises(je.EngineError, match="spatial inertia"):
        je.build_model(scenario_from_parts(body="mass = 1.3\ninertia = [1.0, 5.0, 5.0]"), SIE)


def test_a_process_forked_after_jax_started_refuses_with_an_engine_error(monkeypatch):
    from cross_checks.engines import runtimes
    monkeypatch.setattr(runtimes, "_FORKED_AFTER_JAX", [True])   # what base's fork hook sets in such a child
    sc = load_scenario("projectile")
    said = "forked after JAX started in its parent.*--jobs 1"
    with pytest.raises(je.EngineError, match=said):
        je.simulate(sc, SIE, 0.01, 3)
    with pytest.raises(je.EngineError, match=said):
        je.one_step(sc, SIE, 0.01, np.ones((2, 13)))


def test_the_vmapped_rollout_gives_each_run_its_single_runs_numbers_to_round_off():
    # before: the bodies of a world ran one after the other, their forces called back from the host per step;
    # now vmapped with the forces inside the compiled loop (one body alone: the reproducer's loop, unvmapped)
    names = ["applied_torque", "tennis_racket", "spring_pendulum", "projectile", "velocity_decay"]
    reqs = [RunRequest(load_scenario(n), 0.01, 30 + 7 * i) for i, n in enumerate(names)]
    pairs = je.simulate_many("semi_implicit_euler", reqs[:2])             # a batch of 2
    many = je.simulate_many("semi_implicit_euler", reqs * 3)             # of 15, padded to 16
    for r, run, again in zip(reqs, many, pairs + many[len(pairs):len(reqs)]):
        one = je.simulate(r.scenario, "semi_implicit_euler", r.dt_s, r.n_steps)
        np.testing.assert_array_equal(run.t_s, one.t_s)
        assert run.diverged_at_s is None and len(run.y) == r.n_steps + 1
        scale = np.maximum(1.0, np.abs(one.y))
        for batched in (run, again):
            assert np.max(np.abs(batched.y - one.y) / scale) <= tol.JAXSIM_BATCH_VS_SINGLE
