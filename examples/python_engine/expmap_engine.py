"""A complete rbcheck engine in Python: B free bodies in NumPy, stepped by semi-implicit Euler with an
explicit gyroscopic term and the exponential-map attitude update (MuJoCo's Euler step, reference:expmap_gyro).

rbcheck's loop owns everything else: the forces (applied before every step, held over it), velocity decay,
divergence, recording, the one-step mode and the timing. Register it in your package's pyproject.toml:
    [project.entry-points."rbcheck.engines"]
    expmap = "expmap_engine:ExpmapEngine"
States are packed [x_W (m), v_W (m/s), q_WB (w, x, y, z), ω_W (rad/s, world axes)], one row per body.
"""
import numpy as np
from scipy.spatial.transform import Rotation

from cross_checks.engines.base import SYMPLECTIC_EULER_EXPLICIT_GYRO, Variant
from cross_checks.engines.world import World, WorldEngine


class ExpmapWorld(World):
    """The bodies of ``requests``: mass (B,) kg, inertia I_B (B, 3, 3) kg m² in body axes, gravity (B, 3)."""

    def __init__(self, requests, dt_s: float):
        super().__init__()
        problems = [r.scenario.problem for r in requests]
        self.dt_s = dt_s
        self.m_kg = np.array([p.body.mass_kg for p in problems])
        self.I_B = np.array([p.body.inertia_B for p in problems])
        self.g_W = np.array([p.forces.gravity_W for p in problems], dtype=float)
        self.y = np.zeros((len(problems), 13))
        self.f_W = np.zeros((len(problems), 3))
        self.tau_W = np.zeros((len(problems), 3))

    def set_state(self, y):
        self.y = np.array(y, dtype=float)

    def apply(self, f_W, tau_W):            # world force at the COM (N) and world torque (N m), (B, 3) each
        self.f_W, self.tau_W = np.array(f_W), np.array(tau_W)

    def read(self):
        return self.y.copy()

    def step(self):
        h, y = self.dt_s, self.y
        R_WB = Rotation.from_quat(y[:, 6:10], scalar_first=True)
        v_W = y[:, 3:6] + h * (self.f_W / self.m_kg[:, None] + self.g_W)
        x_W = y[:, 0:3] + h * v_W
        R = R_WB.as_matrix()
        I_W = R @ self.I_B @ np.swapaxes(R, 1, 2)                       # inertia in world axes
        w_W = y[:, 10:13]
        gyro_W = np.cross(w_W, np.einsum("bij,bj->bi", I_W, w_W))      # ω × I_W ω
        w_W = w_W + h * np.linalg.solve(I_W, (self.tau_W - gyro_W)[..., None])[..., 0]
        q = (Rotation.from_rotvec(h * w_W) * R_WB).as_quat(scalar_first=True)
        q *= np.where(np.sum(q * y[:, 6:10], axis=1) < 0, -1.0, 1.0)[:, None]   # stay on q's side
        self.y = np.concatenate([x_W, v_W, q, w_W], axis=1)


class ExpmapEngine(WorldEngine):
    name = "expmap"
    distribution = "scipy"                   # the version recorded with every result
    applies_gravity = True                   # the world adds m g itself: the loop takes it off its force
    variants = {"euler": Variant(1, "semi-implicit Euler, explicit gyroscopic term, exponential-map attitude",
                                 traits=SYMPLECTIC_EULER_EXPLICIT_GYRO)}

    def build(self, requests, variant, dt_s):
        return ExpmapWorld(requests, dt_s)
