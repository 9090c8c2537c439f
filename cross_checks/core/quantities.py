"""The four quantities of a rigid-body state and their error metrics (the definitions every verdict,
file and report shares).

Packed states ``y (..., 13)`` are ``[x_W (m), v_W (m/s), q_WB (w, x, y, z), w_W (rad/s, WORLD)]``.
Errors (per time sample): position ``|x − x_ref|`` (m), velocity ``|v − v_ref|`` (m/s), orientation the
geodesic angle ``2 atan2(|vec(q_ref⁻¹ q)|, |scalar(q_ref⁻¹ q)|)`` (rad, sign-invariant), angular
velocity ``|ω − ω_ref|`` (rad/s, world axes).
"""
from __future__ import annotations

import math

import numpy as np

from reference_sim.quaternion import geodesic_angle
from reference_sim.state import Q, V, W, X

#: The quantities a convergence verdict is given for (docs/results.md).
QUANTITIES = ("position", "orientation", "velocity", "angular_velocity")

#: The block of the packed state holding each quantity, in the state's order.
BLOCKS = {"position": X, "velocity": V, "orientation": Q, "angular_velocity": W}


#: quantity -> column stem in results.csv
COLUMN_STEM = {"position": "pos", "velocity": "vel", "orientation": "orient", "angular_velocity": "angvel"}


UNITS = {"position": "m", "velocity": "m/s", "orientation": "rad", "angular_velocity": "rad/s"}


def unit_q(q):
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def state_errors(y, y_ref) -> dict:
    """Per-sample errors ``{quantity: (T,)}`` of states ``y`` against ``y_ref`` (both (T, 13)).

    The orientation error is the geodesic angle (rad, in [0, π]) and so identical for q and −q;
    quaternions are normalised first (a CSV from another simulator may carry rounding).
    """
    y = np.asarray(y, dtype=float)
    y_ref = np.asarray(y_ref, dtype=float)
    with np.errstate(invalid="ignore"):
        return {
            "position": np.linalg.norm(y[..., X] - y_ref[..., X], axis=-1),
            "velocity": np.linalg.norm(y[..., V] - y_ref[..., V], axis=-1),
            "orientation": geodesic_angle(unit_q(y_ref[..., Q]), unit_q(y[..., Q])),
            "angular_velocity": np.linalg.norm(y[..., W] - y_ref[..., W], axis=-1),
        }


def error_summary(errors: dict) -> dict:
    """``{quantity: {"final": e[-1], "max": max e}}``; NaN where a series is empty or non-finite."""
    out = {}
    for k, e in errors.items():
        e = np.asarray(e, dtype=float)
        if e.size == 0 or not np.all(np.isfinite(e)):
            out[k] = {"final": math.nan, "max": math.nan if e.size == 0 or not np.any(np.isfinite(e))
                      else float(np.nanmax(e))}
        else:
            out[k] = {"final": float(e[-1]), "max": float(e.max())}
    return out


def quantity_scales(y_ref) -> dict:
    """Scale of each quantity along a reference trajectory (at least 1 in its SI unit): the
    magnitude round-off is relative to. Orientation errors are angles in [0, π]: scale π."""
    y_ref = np.asarray(y_ref, dtype=float)
    return {
        "position": max(1.0, float(np.max(np.linalg.norm(y_ref[:, X], axis=-1)))),
        "velocity": max(1.0, float(np.max(np.linalg.norm(y_ref[:, V], axis=-1)))),
        "orientation": math.pi,
        "angular_velocity": max(1.0, float(np.max(np.linalg.norm(y_ref[:, W], axis=-1)))),
    }


def decimation_indices(n: int, max_points: int) -> np.ndarray:
    """At most ``max_points`` indices evenly spread over ``range(n)``, always the first and the last."""
    if n <= max_points:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0, n - 1, max_points)).astype(int))

