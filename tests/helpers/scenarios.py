"""Scenarios for tests: the text of a scenario file from its parts, the few bodies many tests share, and
files written from texts. The format is docs/scenario.md; every builder here writes plain TOML that
``cross_checks.scenario.parse_scenario`` reads like any user's file."""
import tomllib
from pathlib import Path

import numpy as np

from cross_checks.scenario import parse_scenario

SQ = float(np.sqrt(0.5))
#: 90° about world z (w, x, y, z).
YAW90 = f"orientation = [{SQ!r}, 0.0, 0.0, {SQ!r}]"

#: The body most tests spin: 1 kg, principal moments 1, 2, 3 kg m² (asymmetric: a real tumble).
SPINNING_BODY = "mass = 1.0\ninertia = [1.0, 2.0, 3.0]"
#: ω off every principal axis (rad/s, world): torque-free tumbling that has a closed form.
OFF_AXIS_SPIN = "angular_velocity = [0.3, 1.0, 0.2]"
#: The same body spun 10× faster: at Δt = 0.01 s the exponential-map Euler step (reference:expmap_gyro,
#: MuJoCo Euler) blows up at t = 8.65 s (docs/engine_conventions.md).
FAST_SPIN = "angular_velocity = [0.1, 20.0, 0.1]"
GRAVITY = "gravity = [0.0, 0.0, -9.81]"


def scenario_toml(name, duration, dt, dt_ladder=None, *, description=None, reference=None,
                  body=SPINNING_BODY, initial=OFF_AXIS_SPIN, forces="") -> str:
    """The text of a scenario file: the top-level keys, then [body], [initial] and [forces] from the TOML
    lines given for each (``forces`` may hold ``[[forces.spring]]`` tables too). Durations and steps in s."""
    lines = [f'name = "{name}"']
    if description is not None:
        lines.append(f'description = "{description}"')
    lines += [f"duration = {float(duration)!r}", f"dt = {float(dt)!r}"]
    if dt_ladder is not None:
        lines.append(f"dt_ladder = [{', '.join(repr(float(h)) for h in dt_ladder)}]")
    if reference is not None:
        lines.append(f'reference = "{reference}"')
    lines += ["[body]", body, "[initial]", initial]
    if forces:
        lines += ["[forces]", forces]
    return "\n".join(lines) + "\n"


#: A tiny torque-free tumble (0.2 s, two-step ladder): the cheapest scenario with real rotation.
TINY = scenario_toml("tiny", 0.2, 0.01, (0.02, 0.01))


#: Shrunk by the fuzz's 600 s campaign of seed 2026 (docs/fuzz.md §5): a correct scheme pre-asymptotic on its
#: own 3-rung ladder. Every first-order variant shows velocity errors 4.98e-6, 3.5e-6, 2.41e-6 m/s at
#: dt = 0.02, 0.01, 0.005 s (order 0.52); the pairwise orders then go 0.80, 0.91, 0.95 down to dt/32.
PRE_ASYMPTOTIC_ON_ITS_LADDER = '''
name = "fuzz_2026_80"
description = "a body released near rest, strong gravity, a weak spring off the COM"
duration = 0.32
dt = 0.02
dt_ladder = [0.02, 0.01, 0.005]
[body]
mass = 6.0
inertia = [0.03, 0.06, 0.08]
[initial]
velocity = [-0.03, 0.05, -0.01]
[forces]
gravity = [2.0, -9.0, -0.4]
[[forces.spring]]
anchor = [-0.4, -0.09, 0.04]
attach = [0.05, 0.06, 0.01]
stiffness = 0.4
'''


#: Drawn by the fuzz's 600 s campaign of seed 2026, case 10975 (docs/fuzz.md §5): a short torque-free spin,
#: 8–32 steps. reference:rk4's angular velocity errors 1.35e-12, 1.25e-13, 1.08e-14 rad/s (order 3.44 on two
#: resolved rungs): order 4 approached from below (3.44, 3.60, 3.82, 3.91 in long double).
RK4_PRE_ASYMPTOTIC_FROM_BELOW = '''
name = "fuzz_2026_10975"
duration = 0.009713497842287682
dt = 0.0012141872302859603
dt_ladder = [0.0012141872302859603, 0.0006070936151429801, 0.00030354680757149006]
[body]
mass = 13.418062692405062
inertia = [[0.18299685192331938, 0.012506586646448558, -0.03611584042238686], [0.012506586646448558, 0.16803213718941734, -0.02047636314681324], [-0.03611584042238686, -0.02047636314681324, 0.22006208861208057]]
[initial]
position = [0.4965547274889938, 0.6139767823447239, -0.7076226550168009]
orientation = [-0.1591930139186066, -0.2238851904636564, -0.46458784947700604, -0.8418379511098875]
angular_velocity_body = [-10.70141067940838, 0.29551993426424517, 4.560257992746166]
[forces]
gravity = [4.012002558059458, 0.5542993988183263, -2.274065873677227]
'''


def write_scenarios(folder: Path, *texts: str) -> dict:
    """Each scenario text written to ``folder/<its name>.toml``; ``{name: path}`` in the order given."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for text in texts:
        name = tomllib.loads(text)["name"]
        out[name] = folder / f"{name}.toml"
        out[name].write_text(text)
    return out


def scenario_from_parts(body=SPINNING_BODY, initial="", forces="", dt=0.01, duration=1.0):
    """A ground-truth scenario from the text of its [body], [initial] and [forces] tables."""
    return parse_scenario(scenario_toml("t", duration, dt, reference="ground_truth", body=body,
                                        initial=initial, forces=forces))


def state(x=(0, 0, 0), v=(0, 0, 0), q=(1, 0, 0, 0), w=(0, 0, 0)):
    """A packed state (13,) from its parts: x_W (m), v_W (m/s), q_WB (w, x, y, z), w_W (rad/s)."""
    return np.concatenate([x, v, q, w]).astype(float)


def with_body(scenario, mass_kg: float, moment_kg_m2: float):
    """``scenario`` with its body replaced by an isotropic one of this mass and principal moment, past the
    parser's physical ranges (scenario.limits.check_physical_ranges): what an engine adapter may be handed
    through the Python API, to test how it reports a body it refuses."""
    import dataclasses

    from reference_sim.body import RigidBody
    body = RigidBody(mass_kg, moment_kg_m2 * np.eye(3))
    return dataclasses.replace(scenario, problem=dataclasses.replace(scenario.problem, body=body))


def with_initial(scenario, **state):
    """``scenario`` with fields of its initial state replaced (``v_W=[1e9, 0, 0]``), past the parser's
    physical ranges: a run that blows up at once, to test how divergence is handled."""
    import dataclasses
    init = dataclasses.replace(scenario.problem.initial,
                               **{k: np.asarray(v, dtype=float) for k, v in state.items()})
    return dataclasses.replace(scenario, problem=dataclasses.replace(scenario.problem, initial=init))

#: A long run of 10 periods (628 steps) of a spin about the major axis: the long-run stage end to end, fast.
TINY_LONG_RUN = '''name = "tiny_long"
description = "10 periods of a spin about the major axis"
kind = "long_run"
duration = 31.41592653589793
dt = 0.05
[body]
mass = 1.0
inertia = [1.0, 2.0, 3.0]
[initial]
angular_velocity = [0.02, 0.02, 2.0]
'''
