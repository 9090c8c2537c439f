"""Every tolerance rbcheck's verdicts, limits and floors use, each with where its size comes from (the numbers
only tests use are in tests/helpers/tolerances.py: this module is part of the results' cache key).

Machine epsilon ε = 2.2e-16. "Same arithmetic" comparisons allow a few ε times the magnitude; physical
comparisons are derived from the error model of the scheme involved.
"""

#: Fitted convergence order vs expected in the dedicated order studies (tests/reference_sim): ±0.1, a
#: tenth of the gap between neighbouring integer orders.
ORDER_TOL = 0.1

# --- sweeps, metrics and verdicts (cross_checks.analysis, cross_checks.sweep, `rbcheck check`) ------

#: Round-off of a run, relative to a quantity's scale, per step: each step rounds every component
#: by ~ε|y|, and when the increments keep their sign (a falling body) the roundings add up linearly: N ε |y|.
ROUNDOFF_PER_STEP_REL = 2.2e-16
#: Machine epsilon of each precision a variant may declare (engines.base.Traits.precision):
#: numpy.finfo(dtype).eps, 2⁻⁵² (written 2.2e-16 as ROUNDOFF_PER_STEP_REL) and 2⁻²³. Every round-off floor
#: scales with it (metrics.roundoff_floor).
MACHINE_EPSILON = {"float64": ROUNDOFF_PER_STEP_REL, "float32": 2.0 ** -23}
#: How far an engine may store a body's mass and inertia from the scenario's, relative to the largest: a few
#: roundings of the model's text and the engine's arithmetic (jaxsim stores 1.4 kg 1 ulp off); 16 ε still
#: refuses any wrong value a model could get.
ENGINE_MODEL_PARAMETER_REL = 16 * ROUNDOFF_PER_STEP_REL
#: Unit roundoff of each precision (half its ε: the largest relative error of one rounding to nearest): what
#: one step's arithmetic may leave in the one-step defect allowance (analysis.flow.local_allowances).
UNIT_ROUNDOFF = {"float64": 2.0 ** -53, "float32": 2.0 ** -24}
#: A float32 variant's ladder reaches coarser steps where its truncation error shows above float32's round-off
#: (expectations.judged_ladder_s): coarser rungs (half the steps each) are added until this many rungs are
#: expected RESOLVED_ABOVE_FLOOR times above their floors (a fit needs two; one more shows the curvature) ...
PRECISION_LADDER_MIN_RESOLVED = 3
#: ... at most this many (the catalog needs at most 4 at float32: docs/verdicts.md) ...
PRECISION_LADDER_MAX_EXTRA = 6
#: ... while a step turns the fastest motion by at most (p + 1) × this angle ω_c Δt (rad) for an
#: order-p variant: the next term of its error series stays ~(ω_c Δt)/(p + 1) ≤ 15 % of the leading
#: one, and every scheme of the catalog stays stable (RK4's stability interval reaches 2.8 rad) ...
PRECISION_LADDER_STEP_ANGLE_PER_ORDER_RAD = 0.15
#: ... and a run keeps at least this many steps (a ladder point of fewer steps is the initial transient).
PRECISION_LADDER_MIN_STEPS = 16
#: Round-off scatters about its estimate: a point within this factor of its floor, finer than one
#: at the floor, is round-off noise too.
ROUNDOFF_NOISE_FACTOR = 10.0
#: Near an unstable rotation (the tennis racket's and tumbling box's separatrix) the dynamics amplify
#: round-off: an error that grows again at the fine end while below this multiple of the floor is
#: amplified round-off, not a failure to converge (DOP853 at rtol 1e-13 and tumbling_box's closed form part
#: by 2e-9 rad at 10 s).
AMPLIFIED_ROUNDOFF_FACTOR = 1e4
#: The same for a float32 variant (Traits.precision): 1e4 × a float32 floor is the quantity's own scale; 100
#: separates float32 round-off from a missing term's plateau (docs/engine_conventions.md, Rapier).
AMPLIFIED_ROUNDOFF_FACTOR_FLOAT32 = 100.0
#: Fallback only, for a caller with no measurement of its reference (sweeps measure it: see
#: references.reference_error and metrics.roundoff_floor). Accuracy relative to a quantity's scale: closed
#: forms 1e-12 (scipy's Jacobi elliptic functions at arbitrary times), the DOP853 ground truth (rtol 1e-13)
#: 1e-10 of them over 10 s.
REFERENCE_ACCURACY_REL = {"analytic": 1e-12, "ground_truth": 1e-10}
#: A fitted order below this means "does not converge": a consistent scheme has order ≥ 1, an error
#: plateau (missing physics) has order ≈ 0; 0.5 is halfway.
CONVERGES_MIN_ORDER = 0.5
#: Observed vs expected order in a sweep verdict. Expected orders are the integers 1, 2 and 4; ±0.3 separates
#: neighbours with margin and absorbs the curvature left in a 16× ladder once the coarsest pre-asymptotic
#: point is dropped.
SWEEP_ORDER_TOL = 0.3
#: The coarsest ladder point is pre-asymptotic (dropped from the fit when ≥ 3 points remain) when
#: its pairwise order differs from the median of the finer pairs by more than this: half an order
#: is beyond the ±0.3 match tolerance, so keeping it could flip a verdict.
PRE_ASYMPTOTIC_ORDER_DEV = 0.5
#: Energy drift is "secular" when the least-squares trend over the run exceeds this many standard
#: deviations of the residual oscillation (and the round-off floor); otherwise "bounded". A sinusoid
#: fitted over ≥ 1 period leaves a spurious trend below ~1.5 σ of itself; 2 σ keeps it bounded.
SECULAR_TREND_VS_RESIDUAL = 2.0
#: Roundings in a lever arm measured from the world origin (analysis.metrics.lever_roundoff, part of every
#: run's floor for an engine with Traits.lever_arms, in the sweep and the fuzz alike): the COM and the frame
#: origin each rounded (2), the cross product r × F two products and a difference (2 more): 4.
LEVER_ROUNDINGS = 4.0
#: Two variants implementing the same arithmetic (expectations.EQUIVALENT_PAIRS) must agree to this,
#: relative to max(1, |state|): 4e4 steps × ~10 roundings × ε ≈ 1e-10, ×10 for the amplification
#: near the tennis racket's separatrix.
SAME_SCHEME_REL = 1e-9
#: Roundings per step of a same-scheme pair's arithmetic (a quaternion product and normalisation, the
#: force sums): 10, as in SAME_SCHEME_REL's derivation; the pair's allowance over N steps, grown by the
#: measured amplification A, is max(SAME_SCHEME_REL, 10 N ε A) (analysis.metrics.same_scheme_allowance: the
#: sweep's agreement records and the fuzz's agreement property).
SAME_SCHEME_ROUNDINGS_PER_STEP = 10.0
# --- Bring your own engine: any simulator in sweeps, baselines, reports and pytest gates ---

#: Engine files: a first row farther than this from the scenario's initial state (relative to
#: max(1, |state|); rad for the orientation) gets a note in the run's message (the engine may misread
#: the resolved JSON). 1e-5: a CSV printed with 6 significant digits differs from the state by up to 5e-6.
ENGINE_FILE_INITIAL_STATE_REL = 1e-5

# --- bounded work, honest inputs: hardening (docs/hardening.md) ------------------------------------

#: Peak memory of one sweep job per recorded step (its run plus the reference on the same grid): the
#: trajectory is 14 float64 = 112 B, the rest the error arrays, drifts and the reference slice; 1100 covers
#: the growth of a worker's max RSS (docs/hardening.md).
BYTES_PER_RECORDED_STEP = 1100
#: Memory one job may use: 2 GiB, so a laptop with 8 GiB and 4 cores runs 4 jobs side by side and
#: keeps half its memory (~1.9e6 steps per run at BYTES_PER_RECORDED_STEP).
JOB_MEMORY_LIMIT_BYTES = 2 * 2 ** 30
#: The longest line a trajectory CSV may have: the 14 contract columns at full precision take ~350 bytes;
#: 64 KiB leaves room for a thousand extra columns and refuses /dev/zero or a binary file at once.
CSV_MAX_LINE_BYTES = 64 * 1024
#: The largest trajectory CSV read: ~1.9e6 rows (the steps one run may record) of the 14 columns at full
#: precision are ~700 MB; 1 GiB bounds what reading one costs, whatever the file holds.
CSV_MAX_BYTES = 2 ** 30
#: The largest series file (series/<scenario>.npz) a report reads, from its npy headers before any data: a
#: sweep writes at most MAX_SERIES_POINTS (500) points per field, ~15 fields per variant, float64: ~60 kB per
#: variant, 2.4 MB for 40 variants; 256 MiB is 100x that and refuses a 1.9 MB zip of two 2.5e8-element
#: members (4 GB to read, issue 45) before reading it.
SERIES_FILE_MAX_BYTES = 256 * 2 ** 20
#: The largest cache entry read, from its npy headers after its key matched: an entry is one job's record or
#: reference, which JOB_MEMORY_LIMIT_BYTES bounds.
CACHE_ENTRY_MAX_BYTES = JOB_MEMORY_LIMIT_BYTES
#: DOP853 (rtol 1e-13) right-hand-side evaluations per radian of the fastest rate of the dynamics: springs
#: and spins need 64–93; 100 covers both.
DOP853_EVALS_PER_RAD = 100
#: Physical ranges rbcheck judges (scenario.limits.check_physical_ranges; docs/hardening.md). Masses and
#: moments from a 1 mm bead to a ship (MuJoCo refuses them below its mjMINVAL, 1e-15; nine decades either
#: side of 1 keep every term far from float64's range); a moment ratio up to 1e6 (a rod of 1000:1: beyond
#: it the gyroscopic products lose every digit of the small moment's axis); spin, speed, distance and
#: accelerations that, with the duration and step limits, keep every state below ~1e12, where round-off is
#: the floors' ε |y|, not an overflow.
PHYSICAL_MASS_KG = (1e-6, 1e6)
PHYSICAL_INERTIA_KG_M2 = (1e-12, 1e9)
PHYSICAL_MAX_INERTIA_RATIO = 1e6
PHYSICAL_MAX_SPIN_RAD_S = 1e4
PHYSICAL_MAX_SPEED_M_S = 1e4
PHYSICAL_MAX_DISTANCE_M = 1e6
PHYSICAL_MAX_ACCELERATION_M_S2 = 1e6
PHYSICAL_MAX_ANGULAR_ACCELERATION = 1e8
#: Right-hand-side evaluations a scenario's DOP853 reference may need, refused up front beyond it: 300 s of
#: CPU at the slowest cost per evaluation (docs/hardening.md); the catalog needs < 3e4. A count, not a time,
#: so every machine refuses alike.
REFERENCE_EVALS_LIMIT = 1.2e6
#: Wall-time limit of one reference solve while it runs: 3x what REFERENCE_EVALS_LIMIT costs at the
#: slowest evaluation, so only a far too low estimate (or a much slower machine) meets it.
REFERENCE_TIME_LIMIT_S = 900.0
#: Wall-time limit of one run while it runs: the largest run allowed (~1.9e6 steps) at the slowest per-step
#: cost (MuJoCo RK4 evaluating forces in Python, 270 µs) takes ~530 s; 900 s leaves 1.7x for a slower machine.
RUN_TIME_LIMIT_S = 900.0
#: Adjacent rungs of a Δt ladder must differ by at least this ratio. The order from a pair is
#: ln(e_a/e_b) / ln(h_a/h_b); a relative error perturbation δ (the next-order term, a few % at a
#: catalog Δt; round-off near the floor) moves it by δ / ln(ratio). With δ = 5 % and the ±0.3
#: tolerance of a sweep verdict (SWEEP_ORDER_TOL), ln(ratio) ≥ 0.05/0.3 gives ratio ≥ 1.18: 1.2.
MIN_LADDER_RATIO = 1.2
#: Longest scenario name: it becomes file names (scenario-<name>.html, plots/<name>__conservation.png,
#: series/<name>.npz) that must fit the 255-byte limit of common filesystems with room to spare.
MAX_NAME_CHARS = 100

# --- sweep verdicts: measured floors, expectations decided by physics (docs/verdicts.md) --------------------

#: Relative size of the initial-state perturbations that measure the error amplification: far above
#: the references' accuracy (closed forms ~1e-13; DOP853 at AMPLIFICATION_RTOL, whose batched members
#: share their steps), small enough to stay linear (amplification ~1e3: second-order part ~1e-3 of the first).
AMPLIFICATION_EPS = 1e-6
#: DOP853 tolerance of the batched amplification solve: the amplification at (ε, rtol) = (1e-6, 1e-8)
#: equals that at (1e-7, 1e-10) to 4 digits.
AMPLIFICATION_RTOL = 1e-8
#: A DOP853 reference's error is measured as its difference from a solution at this many times its
#: tolerance: the looser solution's error, an upper bound of the reference's.
REFERENCE_CHECK_RTOL_FACTOR = 10.0
#: A closed form's round-off is measured by moving its inputs (initial state, final time) by this many
#: ulps of their scale: a closed form rounds ~1e2 intermediate results (Jacobi elliptic functions plus
#: Carlson integrals), whose errors add like a random walk, ~√100 = 10 ulps; 16 covers it.
CLOSED_FORM_INPUT_ULPS = 16
#: An amplitude drift may bend the fitted order by at most this before the sweep stops claiming an
#: order (verdict "pre_asymptotic"): half the match tolerance SWEEP_ORDER_TOL, the other half left for
#: the scheme's error constants, other error terms and the fit.
AMPLITUDE_MODEL_ORDER_DEV = 0.15
#: An error is used in an order fit only above this multiple of its floor (convergence.fit_convergence):
#: round-off then makes at most a tenth of it, which moves a pairwise order by ≤ log2(1.1) = 0.14 —
#: within AMPLITUDE_MODEL_ORDER_DEV.
RESOLVED_ABOVE_FLOOR = 10.0

# --- `rbcheck check`: a true verdict on any simulator's trajectory (docs/check.md) -----------------

#: Local (one-step) allowance constant C in ``C · h · Δ · M2`` (M2: block majorant of |y''| along the
#: exact flow, see cross_checks.analysis.flow). Every consistent one-step scheme of order ≥ 1 of the
#: θ-family (explicit, semi-implicit, implicit Euler; mid-point and RK schemes have θ = ½) leaves a
#: leading defect Σ_b (θ_b − ½) h² J_b F_b, at most ½ h² M2; the O(h³) remainder adds at most
#: (7/6) h L of that (implicit Euler's Neumann series), ≤ ½ h² M2 while h L ≤ 0.43 (CHECK_MAX_HL).
CHECK_LOCAL_C = 1.0
#: The one-step error model above holds while h L ≤ this (L: the fastest rate of the motion).
CHECK_MAX_HL = 0.43
#: Recorded states of each sweep run from which its one-step defect is measured (spread evenly over the
#: run; each row's defect stands on its own): a wrong equation leaves an O(Δt) defect at every row where its
#: wrong term acts, so 64 rows find it at a small cost per run (docs/check.md).
STEP_DEFECT_ROWS = 64
#: Roundings of one step, in units of the data's unit roundoff times |y| (per component): a step is
#: ~10 operations per component (x + h v, a quaternion product and normalisation); 16 covers them.
CHECK_ROUNDINGS_PER_STEP = 16.0
#: The exact flow's own error (Richardson estimate |y_S − y_2S| / 15 of RK4 with S and 2S substeps) must
#: stay below this fraction of the smallest allowance it is compared with: then it moves no ratio by
#: more than 1 %.
CHECK_FLOW_ERROR_FRACTION = 1e-2
#: RK4 substeps of the exact flow start at ``ceil(L Δ / this)``: (0.1)⁵/120 ≈ 1e-7 relative per substep.
CHECK_FLOW_RATE_PER_SUBSTEP = 0.1
#: Directional finite-difference step (s) for J F in the majorant, divided by max(1, L): central
#: differences then err by ~(τL)² ≈ 1e-12 relative and round off by ε/τ ≈ 2e-10 relative.
CHECK_FD_STEP_S = 1e-6
#: Data printed with at most this many significant digits (or exactly representable in single
#: precision) is taken to be single precision: a float32 needs 9 digits to round-trip.
CHECK_SINGLE_PRECISION_MAX_DIGITS = 9
#: Row intervals are first matched to whole multiples of the median interval within this fraction of it
#: (then every time is checked against n·Δt within the derived single-precision bound).
CHECK_GRID_SLACK = 0.05
#: A row interval spanning more than this many times the typical number of steps is a jump, not a
#: gap (a few dropped rows): the file is refused. 10 accepts up to 9 consecutive missing rows.
CHECK_MAX_GAP_FACTOR = 10.0
#: A quaternion with norm below this (in a file whose quaternions are unit) is "zero": no rotation.
CHECK_ZERO_QUATERNION = 1e-6
#: Rows within this many steps of the scenario's duration count as reaching it (last-step rounding).
CHECK_DURATION_SLACK_STEPS = 0.5
#: Perturbation size (relative to each quantity's scale) used to measure the scenario's error growth:
#: well above the RK4 flow's round-off (1e-16 · growth 1e3), well inside the linear regime.
CHECK_GROWTH_EPS = 1e-7
#: Free-running comparison cap, as a fraction of how far each quantity moves along the reference (an
#: orientation moves at most π: cap 0.31 rad): beyond it an error is a different motion whatever the
#: error model predicts, so the comparison stops being decisive where the allowance reaches it.
CHECK_FREE_RUN_CAP_FRACTION = 0.1
#: A catalogued mistake is named when it explains every step within the local allowance AND at least
#: this many times better (max ratio) than the closest correct scheme.
CHECK_MISTAKE_MARGIN = 4.0
#: Step of the runs that measure a scenario's error growth, as L τ (L: the motion's fastest rate): RK4
#: at L τ = 0.25 errs by ~(0.25)⁵/120 ≈ 1e-5 relative per step, far below what a growth FACTOR needs.
CHECK_GROWTH_RATE_PER_STEP = 0.25
#: "Resembles" a mistake (said with that caution) when it explains 99 % of the steps within this many
#: allowances and CHECK_MISTAKE_MARGIN times better than any correct scheme; beyond, nothing is named.
CHECK_MISTAKE_RESEMBLES = 3.0
#: Schemes whose 99th-percentile step difference from a file is within this factor of the closest one's are
#: as close as it (``check`` names them all, and no "closest scheme" when every scheme ties): the local
#: allowance they are measured in is a bound with a constant C, not sharper than a few tens of percent.
CHECK_CLOSEST_TIE_RATIO = 1.25

# --- compare: a new results directory against the baseline (docs/results.md) ---
#: Relative change of an error or drift that counts as a regression (or improvement): the same code on
#: another machine reproduces errors to ~1e-12 relative (×1e3 at most on the chaotic tumbling cases), while a
#: real change of scheme, default or force semantics changes errors by factors; 5 % separates the two.
COMPARE_REL_TOL = 0.05
#: Absolute change below which an error or drift has not changed: values at the round-off floor
#: (≤ 1e-12) fluctuate by O(1) factors between machines and mean nothing.
COMPARE_ABS_TOL = 1e-12
#: A variant whose errors moved both ways at unchanged orders is a "scheme changed" (another scheme of the
#: same order reorders its error constants by O(1) factors: MuJoCo 3.3.7 -> 4.0.0 RK4 ×0.69 … ×1.91), not a
#: regression, unless one error grew more than this factor: a loss of accuracy whatever improved elsewhere.
COMPARE_SCHEME_CHANGE_MAX_RATIO = 4.0

# --- the second reference: Drake's error-controlled integration (docs/engine_conventions.md) ---
#: Drake runge_kutta5's target accuracy for the second reference: its distances from the primary references
#: are in docs/engine_conventions.md "The second reference"; 1e-14 costs 1.5–2× the time for one more decade.
SECOND_REFERENCE_TARGET_ACCURACY = 1e-13
#: Drake's accuracy is MEASURED as its distance from a second Drake solution at this many times looser
#: target accuracy (an upper bound of its own error, like REFERENCE_CHECK_RTOL_FACTOR for DOP853).
SECOND_REFERENCE_CHECK_FACTOR = 10.0

# --- rbcheck fuzz: hard but fair random cases and their verdicts (docs/fuzz.md) ---------------------------

#: Largest h·L at a case's coarsest step (L: the fastest rate of the motion, measured along the run).
#: A scheme of order p has e(h) = C h^p (1 + c hL + …); over the ladder [h, h/2, h/4] the fitted order
#: moves by ≈ c hL / (2 ln 2). With |c| ≤ 1 (the next term of every scheme here, relative) and half the
#: match tolerance SWEEP_ORDER_TOL (0.3 / 2 = 0.15) for it: hL ≤ 0.15 · 2 ln 2 ≈ 0.2 (a larger c is excused
#: by the two-term rule, FUZZ_TWO_TERM_TOL).
FUZZ_HL_MAX = 0.2
#: Smallest h·L drawn: below it even a first-order scheme's error over a few radians of motion, ~hL·LT,
#: stays a thousand times above the round-off floor; smaller steps only make runs longer.
FUZZ_HL_MIN = 0.005
#: χ = ½ L² h T, the amplitude drift of a first-order step over the run (docs/verdicts.md), drawn
#: log-uniformly in [FUZZ_CHI_MIN, FUZZ_CHI_MAX]. The drift bends a first-order fit to 1 ± χ/2 (its
#: model, physics.amplitude_model_order); at χ = 0.25 that is 0.12, inside AMPLITUDE_MODEL_ORDER_DEV
#: (0.15): the hardest case a first-order scheme must still be claimed on.
FUZZ_CHI_MAX = 0.25
FUZZ_CHI_MIN = 1e-3
#: A χ, the first-order error grown by the measured amplification A, kept ≤ this: the error model is
#: linear in the perturbation, its second-order part ~(A χ)² relative to the first stays below 5 %
#: (an orientation error of ~0.05 rad), so the fitted order is the scheme's and not the motion's.
FUZZ_LINEAR_MAX = 0.05
#: Smallest principal moment over the largest drawn for particle bodies: at 1e-3 the inverse inertia
#: keeps 13 significant digits and the fastest body-frame rate stays within the triangle inequality's
#: |ω̇| ≤ |ω|² (torque-free); thinner bodies are redrawn.
FUZZ_MIN_INERTIA_RATIO = 1e-3
#: A case is measured after its step is chosen; a pilot solve at this tolerance (loose: only rates and
#: the amplification's order of magnitude are needed from it) decides the step.
FUZZ_PILOT_RTOL = 1e-6
#: A case whose MEASURED h·L or A·χ exceeds its bound by more than this factor (the pilot solve misjudged
#: it) is not judged — it is counted as skipped, never as a finding.
FUZZ_BOUND_SLACK = 1.25
#: Smallest relative margin of the triangle inequality I1 + I2 ≥ I3 (1 + margin) of a drawn body. MuJoCo
#: refuses a model whose moments violate A + B ≥ C after its own eigen-decomposition
#: (docs/engine_conventions.md), and a lamina (any three particles) sits exactly on the edge, where
#: round-off (~1e-16 relative) decides; 1e-6 keeps ten orders of magnitude between the two.
FUZZ_TRIANGLE_MARGIN = 1e-6
#: Bullet's btMatrix3x3::solve33 inverts det only when |det| > SIMD_EPSILON = DBL_EPSILON (2.22e-16, Bullet
#: built in double precision as PyBullet is): below it PyBullet maximal's implicit gyroscopic step is wrong.
BULLET_SOLVE33_DET_EPS = 2.220446049250313e-16
#: A free-running ladder is "two-term consistent" (analysis.judge.two_term_consistent) when the third
#: difference of e/h^p is within this fraction of its size: an order-p error with its next term gives 0
#: (plus the third term, ~0.4 (c₃/c₁) h² ≪ 0.25 in the asymptotic range); an order deficit of 0.5 gives 0.38,
#: of 1 gives 0.75. Each error is allowed its round-off floor (it bounds the round-off in it).
FUZZ_TWO_TERM_TOL = 0.25
#: Extra halvings a too-low free-running order is re-judged on before it counts (the fuzz: h/8 … h/32 after
#: (h, h/2, h/4); the sweep: three halvings below its file's finest Δt; analysis.refinement): three more
#: pairs let a slowly converging correct variant reach its order within SWEEP_ORDER_TOL (docs/fuzz.md §5),
#: while a wrong order stays wrong on all of them.
REFINE_HALVINGS = 3

# --- report display tiers (docs/results.md "The report") ---
#: The summary matrix's three greens (display only, never a verdict): the largest final error relative to
#: the scenario's scale at its default Δt below 1e-6 (a tight scheme's reach on the catalog), below 1e-3
#: (the size a plot starts to show), or above.
REPORT_ACCURACY_TIERS = (1e-6, 1e-3)
#: A long run's cell is green (display only, never a verdict) when it keeps what it declares AND its largest
#: drift — the relative energy and |L| drifts and L's turn in rad — is below this: the size a plot starts to
#: show (REPORT_ACCURACY_TIERS[1]). A variant that keeps what it declares but drifts more (a "momentum" step
#: losing energy as expected) is amber: as declared, not conserving.
REPORT_LONG_RUN_CONSERVES = 1e-3

# --- long runs (cross_checks.analysis.long_run, judge.judge_long_run; docs/verdicts.md "Long runs") ---
#: The end of a long run is the mean over its last 5 % (the run's final stretch, ~50 of 1000 periods: many
#: polhode periods, so a bounded oscillation averages out), and its scatter is measured there.
LONG_RUN_END_FRACTION = 0.05
#: A secular drift of the separatrix distance |δ| is named only when |δ| has changed by the end by at least
#: this share of |δ(0)|: a scheme that keeps δ (to round-off, or with a bounded O(Δt²) oscillation) changes
#: it by far less (docs/verdicts.md "Long runs") ...
SECULAR_MIN_CHANGE = 0.02
#: ... and at least this many times the scatter of |δ| at the end (twice its standard deviation over the
#: last LONG_RUN_END_FRACTION: a sinusoid of amplitude A has deviation A/√2, so a bounded oscillation moves
#: its mean from its start by at most A ≤ 0.71 × the scatter, a quarter of 3 × it; a drift, far more).
SECULAR_MIN_TREND_TO_SCATTER = 3.0
#: Points kept of each long run's invariants for the report (series/<long run>.npz): a smooth curve at
#: ~1000 px.
LONG_RUN_SERIES_POINTS = 500


def long_run_roundoff(n_steps: int, unit_roundoff: float, rounding_factor: float = 1.0) -> float:
    """The largest relative change of an invariant a step keeps BY CONSTRUCTION (Traits.keeps) may show after
    ``n_steps`` steps from round-off alone: each step rounds it by at most CHECK_ROUNDINGS_PER_STEP unit
    roundoffs (times the variant's declared rounding factor), and roundings that keep their sign add up
    linearly (the worst case). The Newton solves of the implicit steps
    (reference_sim.integrators.IMPLICIT_TOL) converge quadratically, so they add nothing measurable here."""
    return CHECK_ROUNDINGS_PER_STEP * unit_roundoff * rounding_factor * max(int(n_steps), 1)

# --- progress ---
#: Loading the reference's cached numba kernels takes ~1 s (numba's import and index lookup, measured on 2
#: cores); a warm-up still going after this many seconds is compiling, and the sweep says so (issue 44).
COMPILE_NOTICE_AFTER_S = 3.0

# --- invariance checks (cross_checks.scenario.transforms, judge.judge_invariance; docs/invariance.md) ---
#: Translations of the world origin the sweep's invariance checks make (m): a room (10 m), a site (1 km) and
#: a map tile (10 km), where float32 keeps 4, 2 and 1 mm of resolution (1e4 × 2⁻²³ = 1.2 mm: MuJoCo Warp
#: #1546's regime); all within PHYSICAL_MAX_DISTANCE_M of the catalog's positions.
INVARIANCE_TRANSLATIONS_M = (10.0, 1e3, 1e4)
#: Length and mass factors (k, μ) of the scale transforms: the scale range of the issue, 1e-2 to 1e2 (a
#: 1 cm, 10 g version of a 1 m, 1 kg body and its 100× larger, heavier twin). Within them every catalog body
#: stays inside PHYSICAL_MASS_KG and PHYSICAL_INERTIA_KG_M2 (inertia × μk² from 1e-6 to 1e6).
INVARIANCE_SCALES = ((1e-2, 1e-2), (1e2, 1e2))
#: A broken invariance is run again at Δt/2 and Δt/4 (cross_checks.sweep.invariance): a deviation that is the
#: step's truncation error (a step not covariant under the transform) shrinks with Δt; round-off or a wrong
#: model does not. Two halvings: two pairwise orders, so one lucky ratio cannot decide.
INVARIANCE_REFINEMENTS = (2.0, 4.0)
#: The order each halving's deviation must shrink at to be the step's own: a consistent scheme's truncation
#: error shrinks at order ≥ 1 (its declared order or more), read within the sweep's order tolerance
#: SWEEP_ORDER_TOL (0.3); a wrong model plateaus (order ≈ 0), round-off grows (order < 0). Measured:
#: reference:dlm_splitting on symmetric_top under the body-frame transform, 7.05e-9, 1.76e-9, 4.41e-10,
#: 1.10e-10 rad/s at Δt, Δt/2, Δt/4, Δt/8 (order 2.00 each halving: its splitting along body axes).
INVARIANCE_STEP_MIN_ORDER = 0.7
#: The most welded parts a body may be given as (``[[body.parts]]``): the invariance check splits a body in
#: two; a handful covers a user's composite body, and each part is a body every engine compiles.
MAX_BODY_PARTS = 8
#: The COM-offset transform puts the body frame's origin this many radii of gyration (sqrt(I_max / m)) from
#: the COM: far enough that an engine that ignores the offset is off by a body's size, near enough that the
#: origin stays inside a body of that size.
INVARIANCE_COM_OFFSET_GYRATION_RADII = 1.5
#: The welded split: the child's share of the mass (MuJoCo #3553's "massive fixed child": the larger part)
#: and of the inertia left after the parallel-axis terms, and the distance between the two parts' COMs in
#: radii of gyration (halved until the parts' inertias are physical).
INVARIANCE_SPLIT_CHILD_MASS_FRACTION = 0.75
INVARIANCE_SPLIT_CHILD_INERTIA_FRACTION = 0.6
INVARIANCE_SPLIT_SEPARATION_GYRATION_RADII = 1.0
#: The range a scale factor k or μ may take (a transform outside it is refused, naming k or mu).
INVARIANCE_SCALE_RANGE = (1e-2, 1e2)
#: An invariance check compares two runs of the same variant, each with its own round-off
#: (metrics.roundoff_floor's ε·scale·(b N + √N A) per run): the difference of two runs is bounded by the sum.
INVARIANCE_RUNS_COMPARED = 2
#: Relative slack of a declared invariance finding's size range (engines.base.InvarianceFinding.within): a
#: transform's size is computed from its vector or quaternion (10 km along (2, −3, 6)/7 is
#: 9999.999999999998 m): a few roundings, far below any range a finding declares.
INVARIANCE_FINDING_RANGE_REL = 1e-9
