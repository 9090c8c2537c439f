"""Builders shared by the bring-your-own-engine tests: the example C engine (compiled into a temporary
folder, or its stand-alone Python twin where no C compiler exists), a fake installed distribution
whose entry point registers a Python adapter, and two short scenarios."""
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

from tests.helpers.repo import ROOT

EXAMPLE = ROOT / "examples" / "c_engine"

#: The gyroscopic term matters (anisotropic body, ω off its principal axes): a wrong sign shows.
TUMBLE = """
name = "byo_tumble"
description = "Asymmetric body tumbling off its axes under gravity (the gyroscopic term matters), 1 s"
duration = 1.0
dt = 0.005
dt_ladder = [0.02, 0.01, 0.005, 0.0025]
[body]
mass = 1.5
inertia = [0.4, 0.7, 1.0]
[initial]
velocity = [0.3, 0.0, 2.0]
euler_zxy_deg = [20.0, -35.0, 60.0]
angular_velocity_body = [0.5, 4.0, 0.8]
[forces]
gravity = [0.0, 0.0, -9.81]
"""

#: Every force type of the schema at once, on a particle body (attach/point shifted to the COM).
PUSHED = """
name = "byo_pushed"
description = "Every force type at once: spring off the COM, body-frame force at a point, body torque, drag; 1 s"
duration = 1.0
dt = 0.005
dt_ladder = [0.02, 0.01, 0.005, 0.0025]
reference = "ground_truth"
[body]
particles = [[1.0, 0.3, 0.0, 0.1], [2.0, -0.2, 0.4, 0.0], [1.5, 0.0, -0.3, 0.5]]
[initial]
position = [0.1, 0.0, 0.5]
velocity = [0.2, -0.1, 0.4]
angular_velocity = [0.4, -0.6, 1.2]
[forces]
gravity = [0.0, 0.0, -9.81]
linear_drag = 0.3
[[forces.spring]]
anchor = [0.0, 0.0, 1.0]
attach = [0.1, 0.2, 0.3]
stiffness = 30.0
rest_length = 0.2
[[forces.point]]
force = [0.5, 0.0, 0.2]
point = [0.0, 0.1, 0.1]
frame = "body"
[[forces.torque]]
torque = [0.05, 0.0, -0.1]
frame = "body"
"""


def write_scenarios(folder: Path) -> dict:
    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for text in (TUMBLE, PUSHED):
        name = text.split('"')[1]
        p = folder / f"{name}.toml"
        p.write_text(text)
        out[name] = p
    return out


def c_compiler():
    """The C compiler to build the example with (None: use the Python twin;
    RBCHECK_TEST_NO_CC=1 forces that)."""
    if os.environ.get("RBCHECK_TEST_NO_CC"):
        return None
    return shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")


def compile_cbody(cc: str, folder: Path, broken: bool, name: str = "cbody") -> Path:
    exe = folder / name
    flags = ["-DBROKEN_GYRO_SIGN"] if broken else []
    subprocess.run([cc, "-O2", "-std=c99", *flags, "-o", str(exe), str(EXAMPLE / "cbody.c"), "-lm"],
                   check=True, capture_output=True, text=True)
    return exe


def _python_engine_file(folder: Path, example_toml: str, broken: bool) -> None:
    """The example engine file with its command replaced by the Python twin of cbody.c."""
    lines = []
    for line in (EXAMPLE / example_toml).read_text().splitlines():
        if line.startswith("command = "):
            extra = '"--broken-gyro", ' if broken else ""
            line = f'command = ["{sys.executable}", "cbody.py", {extra}"{{scenario_json}}", "{{out_csv}}"]'
        lines.append(line)
    (folder / example_toml).write_text("\n".join(lines) + "\n")


def build_cbody(folder: Path) -> dict:
    """The example engine ready to run in ``folder``: ``{"good": cbody.toml, "broken": cbody_broken.toml,
    "kind": "C" or "Python"}``. Compiled with the machine's C compiler; without one, the engine files
    run examples/c_engine/cbody.py (standard library only) and a warning says so in the test output."""
    folder.mkdir(parents=True, exist_ok=True)
    cc = c_compiler()
    if cc:
        compile_cbody(cc, folder, broken=False)
        compile_cbody(cc, folder, broken=True, name="cbody_broken")
        for f in ("cbody.toml", "cbody_broken.toml"):
            shutil.copy(EXAMPLE / f, folder / f)
        kind = "C"
    else:
        warnings.warn("no C compiler on this machine: the example engine runs as the stand-alone Python "
                      "script examples/c_engine/cbody.py (same algorithm, standard library only)",
                      stacklevel=2)
        shutil.copy(EXAMPLE / "cbody.py", folder / "cbody.py")
        _python_engine_file(folder, "cbody.toml", broken=False)
        _python_engine_file(folder, "cbody_broken.toml", broken=True)
        kind = "Python"
    return {"good": folder / "cbody.toml", "broken": folder / "cbody_broken.toml", "kind": kind}


FAKE_ENGINE_MODULE = '''
"""A third-party rbcheck engine, installed as a distribution with an entry point (test fixture)."""
import numpy as np

from cross_checks.engines.base import EngineAdapter, Variant
from reference_sim.quaternion import matrix_from_quat, quat_exp, quat_mul
from reference_sim.simulate import Run


#: -1: the correct gyroscopic term; a test sets +1 to plant a regression in variant "euler".
GYRO_SIGN = -1.0


class FakeSimAdapter(EngineAdapter):
    name = "fakesim"
    variants = {
        "euler": Variant(1, "semi-implicit Euler, explicit gyroscopic term, exp-map quaternion"),
        "broken": Variant(1, "the same with the gyroscopic term's sign flipped (planted bug)"),
    }

    def version(self):
        return "2.5"

    def _step(self, problem, y, h, sign):
        body, fm = problem.body, problem.forces
        x, v, q, w = y[0:3], y[3:6], y[6:10], y[10:13]
        R = matrix_from_quat(q)
        f, tau = fm.force_torque(body, x, v, q, R)
        v1 = v + h * f / body.mass_kg
        x1 = x + h * v1
        w_B = R.T @ w
        tau_B = R.T @ tau + sign * np.cross(w_B, body.inertia_B @ w_B)
        w1 = w + h * (R @ np.linalg.solve(body.inertia_B, tau_B))
        q1 = quat_mul(quat_exp(h * w1), q)
        return np.concatenate([x1, v1, q1 / np.linalg.norm(q1), w1])

    def simulate(self, scenario, variant, dt_s, n_steps):
        sign = -GYRO_SIGN if variant == "broken" else GYRO_SIGN
        y = np.empty((n_steps + 1, 13))
        y[0] = scenario.problem.initial_packed()
        for n in range(n_steps):
            y[n + 1] = self._step(scenario.problem, y[n], dt_s, sign)
        return Run(dt_s * np.arange(n_steps + 1), y)

    def one_step(self, scenario, variant, dt_s, y_start):
        sign = -GYRO_SIGN if variant == "broken" else GYRO_SIGN
        return np.array([self._step(scenario.problem, np.asarray(y, float), dt_s, sign) for y in y_start])
'''


def make_fake_distribution(root: Path, entry_points: str = "fakesim = rbcheck_fake_engine:FakeSimAdapter",
                           dist: str = "fake_engine") -> Path:
    """A directory that, on sys.path / PYTHONPATH, is an installed distribution ``dist`` whose
    ``entry_points.txt`` registers ``entry_points`` under rbcheck.engines (a real entry point)."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "rbcheck_fake_engine.py").write_text(FAKE_ENGINE_MODULE)
    info = root / f"{dist}-1.0.dist-info"
    info.mkdir(exist_ok=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist.replace('_', '-')}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[rbcheck.engines]\n{entry_points}\n")
    return root
