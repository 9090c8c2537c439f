"""reports.check_plot: the figure of a check is drawn from the result alone, for full-state and pose-only
files, and for a ladder."""
import dataclasses

import numpy as np
from PIL import Image

from cross_checks.core.trajectory import Trajectory
from cross_checks.engines import run_variant
from cross_checks.gates.check import check_trajectory
from cross_checks.gates.check.ladder import check_ladder
from cross_checks.scenario import load_scenario
from reports.check_plot import check_figure, ladder_figure

SC = dataclasses.replace(load_scenario("particle_body"), duration_s=1.0)


def _traj(dt, present=("position", "velocity", "orientation", "angular_velocity")):
    tr = run_variant(SC, "reference:expmap_gyro", dt, 1.0)
    y = tr.y.copy()
    if "velocity" not in present:
        y[:, 3:6] = np.nan
        y[:, 10:13] = np.nan
    return Trajectory(tr.t_s, y, {"quantities_present": list(present)})


def _size(path):
    with Image.open(path) as im:
        return im.size


def test_a_full_state_and_a_pose_only_figure(tmp_path):
    sc = SC
    full = check_trajectory(_traj(0.01), sc, "full.csv")
    pose = check_trajectory(_traj(0.01, ("position", "orientation")), sc, "pose.csv")
    # particle_body spins: a full-state file gets the polhode column; a pose-only one has no ω to draw it
    for res, name, width in ((full, "full.png", 1800), (pose, "pose.png", 1400)):
        check_figure(res, sc, tmp_path / name)
        assert _size(tmp_path / name) == (width, 880)


def test_a_ladder_figure(tmp_path):
    sc = SC
    results = [check_trajectory(_traj(dt), sc, f"{dt}.csv") for dt in (0.02, 0.01)]
    ladder_figure(results, check_ladder(results, sc), sc, tmp_path / "l.png")
    w, h = _size(tmp_path / "l.png")
    assert w >= 1200 and h >= 400
