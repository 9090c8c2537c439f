"""Each engine's world of free bodies in the engine's own API, importing only NumPy and the engine (never
rbcheck): the adapter (cross_checks/engines/<engine>_engine.py) builds on it, and ``rbcheck repro`` places the
file's code, line for line, into a standalone reproducer (cross_checks/sweep/repro.py; docs/repro.md), without
its docstrings, comments and the definitions the script never reaches (cross_checks/sweep/repro_text.py).

Every module defines ``world(bodies, gravity_W, variant, dt_s)``: a world of ``bodies`` — one
``(mass_kg, moments_kg_m2 (3,), q_BP (w, x, y, z))`` each (principal moments and the principal frame P in body
coordinates) — under gravity ``gravity_W`` (m/s²) at step ``dt_s`` (s), with ``set_state(y)``, ``apply(f_W,
tau_W)``, ``step()``, ``read()`` and ``packed(raw)`` on packed states (B, 13)
``[x_W (m), v_W (m/s), q_WB (w, x, y, z), ω_W (rad/s, world axes)]`` (cross_checks.engines.world's contract).
(MJX's and MuJoCo Warp's ``world`` build on worlds/mujoco.py's model; Brax's, DART's and jaxsim's take the
full inertia tensor as the second item; Drake's takes the principal axes as a rotation matrix R_BP (3, 3), or
None for a diagonal tensor, as the third.)
MuJoCo's, Drake's, DART's and PyBullet's also define ``form_world``: the same with bodies that may also give
their COM in the body frame (m, from its origin) and welded parts (``body_entry`` in the adapter), the
state converted between the COM and the body origin by :mod:`.com` (which imports only NumPy).
tests/cross_checks/engines/worlds/ checks that none imports anything else, and that a reproducer's run of each
(of that compacted code) is the adapter's run, bit for bit.
"""
