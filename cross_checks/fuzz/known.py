"""Engine behaviours a counterexample may show that are documented, measured facts of the engine
(docs/engine_conventions.md): each explainer says, for one violation on one scenario, whether that
behaviour accounts for it. An explained counterexample is still a counterexample (the engine computes
something else than the equations); the explanation tells the user it is the engine, not rbcheck.
"""
from __future__ import annotations

import numpy as np

from cross_checks.core import tolerances as tol

__all__ = ["explain"]


def _bullet_solve33_singular(scenario, violation) -> str:
    """PyBullet maximal coordinates on a body whose I1·I2·I3 is at most BULLET_SOLVE33_DET_EPS (J ≈ I for a
    small Δt): btMatrix3x3::solve33 takes its implicit gyroscopic step as singular (the returned sentence)."""
    if "pybullet:maximal" not in violation.get("variants", []):
        return ""
    det = float(np.prod(np.linalg.eigvalsh(scenario.problem.body.inertia_B)))
    if det > tol.BULLET_SOLVE33_DET_EPS:
        return ""
    return ("PyBullet maximal coordinates solve the implicit gyroscopic step with btMatrix3x3::solve33, "
            f"which treats |det J| ≤ {tol.BULLET_SOLVE33_DET_EPS:.3g} kg³m⁶ (an absolute threshold) as "
            f"singular and then scales by det J instead of dividing; this body's I1·I2·I3 = {det:.3g} kg³m⁶ "
            "is below it, so every step's angular velocity is wrong (docs/engine_conventions.md, PyBullet)")


_EXPLAINERS = (_bullet_solve33_singular,)


def explain(scenario, violation) -> str:
    """The documented engine behaviour that accounts for ``violation`` on ``scenario`` ("" if none)."""
    for f in _EXPLAINERS:
        why = f(scenario, violation)
        if why:
            return why
    return ""
