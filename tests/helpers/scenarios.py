"""Scenario builders shared by the engine adapter tests."""
import numpy as np

from cross_checks.scenario import parse_scenario

SQ = float(np.sqrt(0.5))
#: 90° about world z (w, x, y, z).
YAW90 = f"orientation = [{SQ!r}, 0.0, 0.0, {SQ!r}]"


def scenario_from_parts(body='mass = 1.0\ninertia = [1.0, 2.0, 3.0]', initial="", forces="", dt=0.01, duration=1.0):
    """A ground-truth scenario from the text of its [body], [initial] and [forces] tables."""
    return parse_scenario(f"""
name = "t"
duration = {duration}
dt = {dt}
reference = "ground_truth"
[body]
{body}
[initial]
{initial}
[forces]
{forces}
""")


def state(x=(0, 0, 0), v=(0, 0, 0), q=(1, 0, 0, 0), w=(0, 0, 0)):
    """A packed state (13,) from its parts: x_W (m), v_W (m/s), q_WB (w, x, y, z), w_W (rad/s)."""
    return np.concatenate([x, v, q, w]).astype(float)
