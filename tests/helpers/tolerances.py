"""Tolerances only the tests use: each with a line saying where its number comes from. The package's own
tolerances (every number a verdict, a limit or a floor uses) stay in cross_checks/core/tolerances.py, which is
part of the results' cache key; these are not, so tuning a test never recomputes a cached result.

``from tests.helpers import tolerances as tol`` gives both: this module re-exports the package's names."""
from cross_checks.core.tolerances import *  # noqa: F401,F403 - one namespace for the tests

#: Quaternion algebra vs scipy Rotation: products of unit-norm inputs, a few roundings each: 10 ε.
QUAT_ALGEBRA = 1e-14
#: Readable single-body path vs batched path: same formulas, different evaluation order (einsum vs
#: @, vectorised cross): per-step difference ~ ε|y|, accumulated over ≤ 1000 steps of a bounded
#: problem: 1000 · 10 ε ≈ 2e-12 relative.
READABLE_VS_BATCHED = 1e-11
#: Closed-form discretisation-error predictions matched to 6 significant digits
#: (tests/reference_sim/test_analytic.py).
CLOSED_FORM_PREDICTION_REL = 1e-6
#: tumbling_box: 10 s of a fast (5 rad/s) tumble near the intermediate axis, ~10 flips; the ground
#: truth's error grows through each flip: measured 1.4e-8 at DOP853 rtol 1e-13 and 2.8e-9 at 3e-14,
#: shrinking towards the closed form, so the closed form is the accurate side. 3e-8 = 2x measured.
CLOSED_FORM_VS_GROUND_TRUTH_TUMBLING_BOX = 3e-8
#: reference:course on tennis_racket: its final orientation error must stay above this at every dt:
#: the physical body has flipped (≈ π away); 1 rad is far from any discretisation error.
COURSE_NONCONVERGENCE_MIN_RAD = 1.0
#: Projectile closed forms (semi-implicit x_n = x0 + n h v0 + g h² n(n+1)/2 and the exact parabola):
#: 100 steps of sums of ≤ 3 m quantities, ~100 ε · 3 ≈ 7e-14; the required bound is 1e-12.
AGREE_PROJECTILE = 1e-12
#: The same scheme (symplectic Euler, explicit gyroscopic term, exponential map) in NumPy, MuJoCo
#: Euler and PyBullet multibody over ≥ 2000 steps: round-off only (measured ≤ 1e-13); the required
#: bound is 1e-10 in position, orientation and angular velocity.
AGREE_SAME_SCHEME = 1e-10
#: mujoco:implicitfast vs pybullet:maximal, torque-free tennis racket, 2 s at 1e-3: both take the same
#: linearised implicit gyroscopic step (Bullet's body-frame Newton step == MuJoCo's implicit
#: derivative for a lone free body), so only round-off separates them: measured 3.2e-14 rad (7.8e-13
#: over the full 10 s, where the unstable intermediate axis amplifies it); 1e-11 leaves 300x margin.
AGREE_IMPLICIT_PAIR_TORQUE_FREE = 1e-11
#: With an applied torque they differ at first order (Bullet adds h I⁻¹τ outside the implicit solve,
#: MuJoCo solves (I + h D) Δω = h (τ − ω×Iω)): the 2-s difference must halve with h (ratio 2 ± 0.2).
AGREE_FIRST_ORDER_RATIO = (1.8, 2.2)
#: MuJoCo implicit vs implicitfast for a lone free body (docs/engine_conventions.md: 1e-13): measured 8e-18.
AGREE_IMPLICIT_VS_IMPLICITFAST = 1e-13
#: The body has flipped when its y axis points against world y (R[:, 1]·e_y < 0): measured −0.9996 for
#: every gyroscopic scheme; the course update never gets below +0.9999. Thresholds far from both.
AGREE_FLIP_BELOW = -0.5
AGREE_NO_FLIP_ABOVE = 0.5
#: The recorded t = 0 row vs the scenario's initial state: ω goes world -> body -> world (MuJoCo) or the
#: quaternion through x,y,z,w and the principal frame (PyBullet): a few ε of |ω| ≤ 5 rad/s.
AGREE_INITIAL_ROW = 1e-14
#: Same-arithmetic conversions at an adapter's boundary (MuJoCo: qpos/qvel <-> packed state, one rotation
#: of a unit vector; PyBullet: quaternion order, principal-frame rotation): a few ε.
ADAPTER_ROUND_TRIP = 1e-15
#: A full inertia tensor through its principal frame (world.principal_spec): R_BP diag(moments) R_BPᵀ of
#: LAPACK's eigh (backward error a few ε ‖I‖) and R_BP through q_BP and back (a few roundings of entries ≤ 1),
#: relative to ‖I‖ and 1: 1e-14.
PRINCIPAL_FRAME_ROUND_TRIP = 1e-14
#: The contract suite (tests/cross_checks/engines/test_contract.py), in units of the variant's rounding unit ε
#: (float64 or float32), relative to max(1, |state|): the state set then read back goes through the engine's
#: own layout (ω rotated into body axes and back: two products with a rotation built from q, ~8 roundings
#: each; float32 engines round every component once more): 16 ε.
CONTRACT_ROUND_TRIP_EPS = 16
#: One step against its closed form (Δv = g Δt from rest; v scaled by γ), or one_step from a recorded state
#: against the recorded next state: the round trip above, amplified by one step of O(1) numbers, plus the
#: step's own few roundings: 64 ε. A wrong force (the weight twice: Δv off by g Δt ≈ 0.1 m/s) or a decay
#: left out (1 − γ ≈ 1e-2) is 10⁴–10¹³ times beyond it.
CONTRACT_ONE_STEP_EPS = 64
#: The World API's example engine (SciPy rotations, NumPy solve) against reference:expmap_gyro, the scheme it
#: implements, relative to max(1, |state|): the same arithmetic in another order, ε per rounding over ≤ 1e4
#: steps of a motion that amplifies little (measured 1.2e-13 on tennis_racket's 1e4 steps): 1e-10. A
#: first-order difference of scheme (another gyroscopic step, the attitude update on the other side) is
#: ≥ 1e-4.
EXAMPLE_ENGINE_VS_ITS_SCHEME = 1e-10
#: one_step from a recorded state against the recorded next state: CONTRACT_ONE_STEP_EPS, and an implicit
#: step's Newton iterations, each rounding (Drake's implicit Euler: measured 127 ε on spring_pendulum): 256 ε.
CONTRACT_RESTART_EPS = 256
#: Exact exponential-map spin about a principal axis over 100 steps: each step rounds the quaternion
#: product (~ε; MuJoCo also renormalises): 100 · a few ε.
ADAPTER_SPIN_100_STEPS = 1e-13
#: one_step from a recorded state vs the recorded next state: the same engine step from the same doubles,
#: up to the boundary conversions (MuJoCo: ω body -> world -> body, two roundings of |ω|; PyBullet: the
#: principal-frame rotation of full tensors and the x,y,z,w order): a few ε.
ADAPTER_ONE_STEP_REPLAY = 1e-14
#: Semi-implicit closed form of a projectile (h = 0.01, 1 s): sums of 100 terms of size ≤ 3 m: 100 ε · 3.
PYB_PROJECTILE_EXACT = 1e-12
#: PyBullet's default multibody damping must visibly fail the projectile: docs/engine_conventions.md measured
#: 0.15 m after 1 s; anything above 1 cm is far outside discretisation (which is exactly zero here).
PYB_DEFAULT_DAMPING_MIN_ERROR = 1e-2
#: mujoco:rk4 vs DOP853 (GROUND_TRUTH_RTOL) on tennis_racket at dt = 1e-3: the required bound.
MJ_RK4_VS_GROUND_TRUTH = 1e-8
#: Observed convergence order of mujoco:rk4 with per-stage forces vs 4 (measured 3.99-4.03 on these
#: ladders, whose errors stay 3+ decades above round-off); ORDER_TOL of the suite is 0.1.
MJ_RK4_ORDER_TOL = 0.1
#: The same with forces held over the step (xfrc_applied fixed over the 4 stages): first order;
#: measured 0.96-1.01.
MJ_HELD_ORDER_TOL = 0.1
#: Fitted order of Drake's RK2/RK3 on spring_pendulum's 1 s ladder (4e-3 … 1e-3): measured 1.97–3.01;
#: with forces held over the step RK3 measures ~1.0. 0.15 separates every pair by far.
DRAKE_ORDER_TOL = 0.15
#: Drake's derivatives vs the hand-derived ω̇_W = I_W⁻¹(τ − ω × I_W ω), a = f/m + g: a 3×3 solve, a few ε.
DRAKE_DERIVATIVE_REL = 1e-13
#: A principal-axis spin through 50 RK3 steps at ωΔt = 0.02: local error ~(ωΔt)⁴/24 per step, ~1e-7 rad.
DRAKE_SPIN_RK3 = 1e-6
#: |q| − 1 of Drake's (unnormalised) quaternion after 200 semi-explicit Euler steps of 0.01 s on the
#: tennis racket: ~Σ (|ω|Δt)²/8 ≈ 200 · 5e-5 = 1e-2 (measured 1.2e-2); 1e-3 says "it drifts".
DRAKE_QUATERNION_DRIFT_MIN = 1e-3
#: drake:runge_kutta3 at Δt = 1e-3 on the tennis racket over 10 s: ~C (ωΔt)³ ωT ≈ 1e-7 rad.
DRAKE_RK3_TENNIS_RAD = 1e-6
#: DART state round trips at the boundary (quaternion -> rotation vector -> DART's expMapRot / AngleAxis and
#: back): a handful of roundings of unit-size numbers, measured ≤ 4e-16; a few ε.
DART_ROUND_TRIP = 1e-15
#: One DART step vs the hand-derived semi-implicit Euler step from the same doubles: a 3×3 solve, a
#: Rodrigues matrix and DART's log map, measured ≤ 3.4e-16 in R and exactly 0 in ω and v: 10 ε.
DART_HAND_STEP = 2e-15
#: DART's rotation update below |ω|Δt = 1e-3 rad is I + S + S²/2 (dart/math/Geometry.cpp expMapRot): its
#: angle exceeds the exact one by θ³/6 (+ O(θ⁵)); the measured excess must be that within 1 %.
DART_TAYLOR_EXCESS_REL = 1e-2
#: Same scheme as MuJoCo Euler where every step turns by more than 1e-3 rad (tennis racket, 2 s at 1e-3 s,
#: |ω|Δt ≈ 2e-3): measured 7e-13 rad over 10 s; the required bound.
DART_SAME_AS_MUJOCO_EULER = 1e-10
#: spring_pendulum (ω passes through 0, so many steps turn by < 1e-3 rad): DART vs MuJoCo Euler measured
#: 1.8e-8 rad/s over 5 s at its dt, 5 decades above that pair's round-off; "differs" means beyond 1e-10.
DART_TAYLOR_BRANCH_MIN_DIFF = 1e-10
#: jaxsim conventions read back through jaxsim's own conversions (Mixed <-> inertial velocities,
#: the transform of a quaternion): a few roundings of unit-size numbers (measured ≤ 2e-16 on the
#: tilted body at (1, −2, 0.5) m).
JAXSIM_ROUND_TRIP = 1e-15
#: One jaxsim semi-implicit Euler step vs the hand-derived step in the inertial representation: a 3×3 solve,
#: cross products of numbers up to ~10; measured 0 in ω and x, 2.2e-16 in v and q: 10 ε scaled.
JAXSIM_HAND_STEP = 2e-14
#: One jaxsim RK4 step vs reference_sim's RK4 of the same ODE with the start force held (another
#: implementation: inertial-representation variables, Baumgarte term on the stage quaternions, O(h⁵) apart).
JAXSIM_RK4_VS_REFERENCE_STEP = 1e-9
#: one_step from a recorded state vs the free run's next row: the same compiled step, vmapped vs in a loop
#: (XLA may fuse them differently): a few ε of numbers of order 10.
JAXSIM_REPLAY_REL = 1e-13
#: simulate_many (a vmapped batch, any size from 2) vs simulate (one body, the reproducer's loop, unvmapped):
#: the same step, vectorised by XLA (batches of 2 and 16 differ in the last bit too); measured ≤ 8e-15
#: absolute on states of order 1-10 over 120 steps (spring_pendulum), relative to max(1, |y|): 10× that.
JAXSIM_BATCH_VS_SINGLE = 1e-13
#: Fitted orders of jaxsim's variants on the short catalog ladders used by its tests
#: (measured: see the "jaxsim 0.9" section of docs/engine_conventions.md); ORDER_TOL of the
#: suite is 0.1, ladders this short 0.15.
JAXSIM_ORDER_TOL = 0.15
#: jaxsim:semi_implicit_euler vs reference:course_gyro (the same rotation update) over the first second of a
#: fast spin (|ω|Δt = 0.2 rad per step): measured 4.3e-13 rad/s of 20 rad/s.
JAXSIM_SAME_ROTATION = 1e-11
#: jaxsim RK4 in a world turned by the invariance rotation, mapped back, vs its run of the original over 500
#: steps (particle_body, spring_pendulum): two roundings of the same motion in frames turned about z; measured
#: 3.1e-14 rad/s over particle_body's 5000 steps. Before the adapter turned its frame: 0.166 rad/s (5000
#: steps), 0.0166 rad/s over these 500.
JAXSIM_TURNED_WORLD = 1e-11
#: Genesis (genesis-world 1.4.5, float64, fast-math kernels) state round trips at the boundary
#: (quaternion, ω_W <-> ω_B through the rotation, Genesis's forward pass): a few roundings of
#: unit-size numbers; measured ≤ 4e-16.
GENESIS_ROUND_TRIP = 2e-15
#: Genesis's joint-space mass matrix of the free body vs diag(m 1, I_B): assembled from the tensor rotated by
#: the principal-axes quaternion MuJoCo's compiler computed and back: measured ≤ 1e-15 on unit-size moments.
GENESIS_MASS_MATRIX = 1e-14
#: A force and torque read back from one step of 1 ms from rest (m Δv/Δt, I_W Δω/Δt): Δv/Δt divides round-off
#: of 1e-3-size velocities by 1e-3: ~1e-13.
GENESIS_WRENCH = 1e-11
#: One Genesis step vs the hand-derived step of its scheme from the same doubles (a 3×3 solve, a quaternion
#: exponential): measured ≤ 5e-16; 10 ε.
GENESIS_HAND_STEP = 2e-15
#: The implicit midpoint equation's residual I (ω1 − ω0)/Δt − (τ − ω̄ × I ω̄) (N m) after Genesis's
#: Newton iteration, which stops at 1e-13 relative to the momentum scale (func_midpoint_free_body):
#: 2/Δt |I ω| ~ 1e3 here, so 1e-10.
GENESIS_MIDPOINT_RESIDUAL = 1e-9
#: Kinetic energy drift of a torque-free full-tensor tumble over 200 midpoint steps: the Newton tolerance per
#: step (1e-13) summed: measured ~1e-14; the required bound.
GENESIS_MIDPOINT_ENERGY_REL = 1e-11
#: genesis:euler vs mujoco:euler on applied_torque, 200 steps of 0.01 s: the same scheme; Genesis's fast-math
#: kernels reorder a few roundings: measured 2.3e-15.
GENESIS_SAME_AS_MUJOCO_EULER = 1e-12
#: one_step from a recorded state vs the free run's next row: the same step through the boundary conversion
#: (ω_W -> ω_B -> ω_W): measured ≤ 9e-16.
GENESIS_REPLAY_REL = 1e-13
#: Brax (cross_checks.engines.brax_engine), float64. State round trips at the boundary (quaternion
#: rotations of ω between body and world axes, brax's kinematics.forward): a few roundings of
#: unit-size numbers, measured ≤ 5e-16.
BRAX_ROUND_TRIP = 1e-15
#: MuJoCo's compiler diagonalises the full tensor (principal moments + iquat, its iterative eigensolver) and
#: the test rebuilds R diag(I) Rᵀ: measured 4e-14 on moments of 2–4 kg m²; 1e-13.
BRAX_INERTIA_ROUND_TRIP = 1e-13
#: One brax step vs the hand-derived step from the same doubles (a 6×6 solve, quaternion products): a few ε.
BRAX_HAND_STEP = 1e-14
#: The generalized rotation update turns by Δt(|ω| + 1e-8) about ω/(|ω| + 1e-8) (brax's
#: guard against |ω| = 0): 1e-10 rad in a step of 0.01 s, above round-off; the hand step's
#: exact exp map is that close.
BRAX_ROTATION_BIAS = 1e-9
#: The positional pipeline's velocity is (x₁ − x₀)/Δt (project_xd): the round-off of positions of size ~2 m
#: over Δt = 0.01 s, ε·2/0.01 ≈ 4e-14; 1e-12 leaves room (the sweep measures it growing like 1/Δt).
BRAX_POSITIONAL_VELOCITY = 1e-12
#: one_step from a recorded state vs the free run's next row: pipeline.init rebuilds the state from q and q̇
#: (and the positional velocity projection divides round-off by Δt): measured ≤ 5e-14 relative.
BRAX_REPLAY_REL = 1e-12
#: A run batched with other Δt (vmap) vs alone: XLA may vectorise the batch differently, a few ε per step
#: compounding over up to 700 steps of a tumble; measured 0.
BRAX_BATCH = 1e-10
#: A body at 1e4 m/s spinning at 100 rad/s for 100 MJX steps: MJX's spatial-velocity arithmetic mixes the two,
#: measured 2.1e-12 m/s of drift across (≈ ε × 1e4); the bound 1e-10 (a clamp or a sleep would be O(1)).
MJX_FAST_BODY = 1e-10
#: MJX (mujoco-mjx 3.17.0, float64) vs MuJoCo C Euler, the same arithmetic in another order of sums:
#: measured ≤ 1.7e-13 relative (max(1, |state|)) on tennis_racket, applied_torque and spring_pendulum at
#: their own Δt and duration; float32 would be ~1e-7. The bound: 1e-11. (tumbling_box, 10 s near a
#: separatrix that amplifies round-off ~1e3: 1.8e-12 on its ladder, 8.6e-11 at its Δt of 1 ms — held to
#: the sweep's SAME_SCHEME_REL.)
MJX_SAME_AS_MUJOCO_EULER_REL = 1e-11
#: One MJX Euler step vs the hand-derived semi-implicit step from the same doubles (MJX's RNE, a Cholesky
#: solve, its quaternion exp map vs NumPy's): measured ≤ 3.6e-16 (RK4's hand step: ≤ 6e-17); 10 ε.
MJX_HAND_STEP = 2e-15
#: one_step from a recorded state vs the free run's next row: the same step through the body/world ω
#: conversion at the boundary (and the force model called on the host from the compiled loop or before it):
#: measured ≤ 5.2e-16 relative.
MJX_REPLAY_REL = 1e-14
#: simulate_many (vmapped, batch of 4) vs simulate (batch of 1): the same executable's arithmetic per member,
#: measured 2.0e-15 on symmetric_top (XLA vectorises a batch of 4 differently from one member); 5× that.
MJX_BATCH_VS_SINGLE = 1e-14
#: mjx:implicitfast vs mjx:euler on the tennis racket (300 steps of 0.01 s): Cholesky vs LDLᵀ of the same M,
#: measured 0 (bit for bit; 0 on the whole catalog in the sweep's agreement check too).
MJX_IMPLICITFAST_VS_EULER = 1e-12
#: MuJoCo C's implicitfast (implicit gyroscopic term) vs MJX's (none) on the same run: measured 2.4e-3 rad/s;
#: "differs" means beyond 1e-6, 7 decades above MJX vs MuJoCo Euler's round-off.
MJX_IMPLICITFAST_VS_C_MIN_DIFF = 1e-6
#: An error ratio at h and h/2 against 2^p for order p: asymptotic only up to the next term, ±15 % (as
#: DRAKE_ORDER_TOL for fitted orders).
MJX_ORDER_RATIO_REL = 0.15
#: mjx:rk4 where RK4 is exact (a spin about a fixed principal axis, constant world force and torque along it:
#: a polynomial motion): final-state errors measured 7.1e-13 and 7.3e-13 at Δt = 0.05 and 0.025 s over 2 s —
#: the round-off of the MuJoCo C RK4 reference at Δt/64; a fourth-order error at these steps would be ~1e-6.
MJX_RK4_EXACT = 1e-11
#: One step of a new gyroscopic scheme vs its transcription from its source (tests/helpers/oracle.py): the
#: same maths by other operations (scipy rotations, principal frames, fsolve to a 1e-14 residual) on O(1)
#: quantities: a few tens of ε.
GYRO_ONE_STEP = 1e-13
#: A quantity a scheme keeps by construction (|L|, L, the energy), relative, over ≤ 5000 steps: one rounding
#: of ε per step, adding up at worst linearly: 5000 · 2.2e-16 ≈ 1.1e-12; measured ≤ 3e-14 on these runs.
KEPT_TO_ROUNDOFF = 2e-12
#: Bullet's body- and world-axes implicit steps are one step in exact arithmetic: 2000 steps of a stable
#: tumble apart by round-off only (measured ~1e-14 rad); 1e-11 leaves a wide margin.
SAME_STEP_TWO_AXES = 1e-11

# --- quaternion round trips, closed forms, the float32 adapters' hand-written steps ---
#: Round trips through matrices / axis-angle / Euler angles: each conversion loses ~10 ε, and the
#: acos/atan2 near 0 or π amplify it by ~1/sin; 1e-12 rad covers the test sets (measured ≤ 4e-15).
QUAT_ROUND_TRIP = 1e-12
#: Euler-angle round trip near gimbal lock: y and z come from atan2 of entries scaled by cos(pitch),
#: so their error is ~ε/|cos pitch| (conditioning of the parameterisation, not of the rotation);
#: 10 ε / |cos pitch| covers it (hypothesis found 2.3e-11 rad at cos pitch = 2e-5, i.e. 2.3 ε/cos).
#: At lock (|cos pitch| < the gimbal threshold 1e-9 of euler_zxy_from_quat) z is set to 0 by
#: convention, dropping a rotation of at most ~2·|cos pitch|: the round trip is exact to 2e-9 rad.
def euler_round_trip_tol(cos_pitch: float, locked: bool = False) -> float:
    if locked:
        return QUAT_ROUND_TRIP + 2e-9
    return QUAT_ROUND_TRIP + 10 * 2.2e-16 / max(abs(cos_pitch), 1e-300)


#: Closed forms vs DOP853 ground truth (rtol 1e-13, reference_sim.ground_truth) over 10 s: ≤ 1e-10, two orders
#: below the smallest error any verdict resolves.
CLOSED_FORM_VS_GROUND_TRUTH = 1e-10

#: One mujoco_warp step (float32) vs the scheme written out by hand in NumPy (float64) from the same state,
#: for values of size ~1-3 (m/s, rad/s): measured ≤ 7.1e-8 (Euler), 4.9e-8 (implicit), 5.8e-8 (RK4's
#: attitude), i.e. ≤ 0.6 ε32; 1e-6 (8 ε32) keeps 20× below the nearest wrong schemes measured on the same
#: step (RK4 without the Munthe-Kaas correction 2e-5 rad, the correction's other sign 3.9e-5 rad, Euler for
#: the implicit family 1e-2).
MJW_HAND_STEP = 1e-6
#: mujoco_warp (float32) vs MuJoCo C (float64) with the same integrator, relative to max(1, |state|), over
#: 100 steps of 10 ms on tennis_racket, applied_torque, spring_pendulum and velocity_decay: measured ≤ 3.5e-6
#: (spring_pendulum's ω; the float32 roundings of 100 steps); the nearest wrong schemes there differ by 1.5e-4
#: (MuJoCo C Euler vs the implicit step, tennis_racket) and 0.22 (RK4 with the forces held over its stages).
MJW_SAME_AS_MUJOCO_REL = 2e-5
#: RK4's per-stage force kernel (float32) vs forces.stage_force_torque (float64), relative to
#: max(1, |wrench|), on 40 random states: a handful of float32 roundings of products of O(1) numbers;
#: measured ≤ 2.6e-7; 2e-6.
MJW_STAGE_FORCES_REL = 2e-6

#: One PhysX step against the same step written out in float64 numpy, absolute on values of order 1 (m, m/s,
#: rad, rad/s): PhysX computes in float32 (ε = 1.2e-7): measured ≤ 7e-8 for PGS (ω, v, x, q) at Δt = 0.01 s.
PHYSX_HAND_STEP = 4 * 2.0 ** -23
#: The same for TGS's angular velocity, relative to |ω|: TGS turns ω into sqrt-inertia space and back with two
#: float32 world matrices every step: measured 1.2e-6 relative (10 ε₃₂) on an isotropic spin, 2.6e-6 absolute
#: on |ω| = 1.7 rad/s with a full tensor, independent of Δt; 4e-6 relative leaves room, and the candidate
#: schemes PhysX's step is not (plain explicit gyroscopic term, none) are ≥ 6× farther at Δt = 0.05 s.
PHYSX_TGS_OMEGA_STEP_REL = 4e-6

# --- the report's pictures (reports/polhode.py; tests/reports/test_polhode.py) ---
#: The closed-form polhodes (sphere ∩ energy ellipsoid) are evaluated in float64 from a handful of square
#: roots: |P| and Σ P_i²/I_i along them hold to a few ulps (2.2e-16 each) of the terms; 1e-12 leaves ~1000×.
POLHODE_CLOSED_FORM = 1e-12
#: How far (rad) L's direction in body axes may move along a run whose ω is fixed in body axes (the course's
#: step, no gyroscopic term, on a torque-free body: ω_W constant, the body spins about it) as read from the
#: report's float32 series: q and ω each rounded to 6e-8 relative, the direction computed from them to ~10×
#: that; 1e-5 leaves a margin of ~20×, and the reference's L turns by π (the flip) on tennis_racket.
POLHODE_FIXED_RAD = 1e-5

#: The fuzz's amplification estimate (stacked DOP853 at AMPLIFICATION_RTOL, sampled over the run) against the
#: sweep's (references.error_amplification: its own batched DOP853 at the same rtol, at the final time) on a
#: motion whose amplification peaks at the end: the same estimate (references.amplification_of) from two
#: solves whose error, ~1e-8 of the state, is ~1e-2 of the 1e-6 perturbations; 4 digits agree
#: (core/tolerances.py AMPLIFICATION_RTOL), 1e-3 relative.
AMPLIFICATION_TWO_SOLVES_REL = 1e-3
#: The most lines `rbcheck repro mujoco:rk4 tennis_racket --claim order orientation` may write. Issue 47 asks
#: for "about 60 lines for MuJoCo" (MuJoCo #3553's report was under 30); measured: 214 lines with the world
#: and the measurement embedded whole, 131 compacted (cross_checks/sweep/repro_text.py: docstrings, comments
#: and unreached definitions left out, the numbers gathered), 143 once the order claim said which Δt
#: diverged. Then 112 (docs/repro.md, "Length"): the code sliced to what the script's numbers reach
#: (cross_checks/sweep/repro_slice.py: the welded parts' loop, the other quantities' error), the header in
#: three lines and the imports in two, MuJoCo's world and the order verdict written more compactly at their
#: source. Of the 112, 51 are the MuJoCo world itself (the adapter's code, which the script may not replace
#: by a shorter hand-written copy), 45 the measurement, 16 the header, imports, blank lines and numbers.
#: 4 lines of headroom let the world gain a line or two without this failing; more means the script grew
#: and this number must be measured and justified again.
REPRO_MUJOCO_ORDER_MAX_LINES = 116
