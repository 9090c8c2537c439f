"""The trajectory CSV reader: columns by name (docs/trajectory.md), what it accepts and what it refuses."""
import numpy as np
import pytest

from cross_checks.core.trajectory import COLUMNS, Trajectory, TrajectoryError

ROW0 = dict(zip(COLUMNS, [0, 1, 2, 3, 4, 5, 6, 1, 0, 0, 0, 7, 8, 9]))
ROW1 = dict(ROW0, t=0.5, x=1.5)


def _write(path, header, rows):
    path.write_text(",".join(header) + "\n"
                    + "".join(",".join(str(r[c]) if c in r else "junk" for c in header) + "\n"
                              for r in rows))
    return path


def test_written_trajectories_read_back_exactly(tmp_path):
    t = np.array([0.0, 0.1, 0.30000000000000004])
    y = np.random.default_rng(0).normal(size=(3, 13))
    Trajectory(t, y, {"engine": "x"}).write(tmp_path / "a.csv")
    back = Trajectory.read(tmp_path / "a.csv")
    assert np.array_equal(back.t_s, t) and np.array_equal(back.y, y)
    assert back.meta["engine"] == "x"


def test_columns_are_read_by_name_in_any_order_with_extra_columns_ignored(tmp_path):
    header = ["qz", "wy", "t", "frame", "vx", "x", "qw", "y", "wx", "vz", "z", "qx", "vy", "qy", "wz"]
    back = Trajectory.read(_write(tmp_path / "a.csv", header, [ROW0, ROW1]))
    assert back.t_s.tolist() == [0.0, 0.5]
    assert back.y[0].tolist() == [ROW0[c] for c in COLUMNS[1:]]
    assert back.y[1, 0] == 1.5
    assert back.meta["quantities_present"] == ["position", "velocity", "orientation", "angular_velocity"]


def test_pose_only_files_read_with_nan_velocities_when_allowed(tmp_path):
    path = _write(tmp_path / "pose.csv", ["t", "x", "y", "z", "qw", "qx", "qy", "qz"], [ROW0, ROW1])
    with pytest.raises(TrajectoryError, match="velocity columns vx,vy,vz missing"):
        Trajectory.read(path)
    back = Trajectory.read(path, require=())
    assert back.meta["quantities_present"] == ["position", "orientation"]
    assert np.all(np.isnan(back.y[:, 3:6])) and np.all(np.isnan(back.y[:, 10:13]))
    assert back.y[1, 0] == 1.5


@pytest.mark.parametrize("header, rows, words", [
    (["x", "y", "z"], [ROW0], "no column 't'"),
    (["t", "x", "y", "z", "qw", "qx", "qy"], [ROW0], "orientation needs all of qw,qx,qy,qz; missing qz"),
    (["t", "t", "x"], [ROW0], "column 't' appears twice"),
    (["t", "extra"], [ROW0], "no state columns"),
    (list(COLUMNS), [], "no data rows"),
    (list(COLUMNS), [ROW0, ROW0], "line 3: column t: times must strictly increase"),
    (list(COLUMNS), [ROW0, dict(ROW1, t="nan")], "line 3: column t: time must be finite"),
    (list(COLUMNS), [ROW0, dict(ROW1, vy="abc")], "line 3: column vy: not a number"),
])
def test_bad_files_name_the_line_column_and_reason(tmp_path, header, rows, words):
    with pytest.raises(TrajectoryError, match=words.replace("(", r"\(")):
        Trajectory.read(_write(tmp_path / "bad.csv", header, rows), require=())


def test_a_short_line_is_refused(tmp_path):
    path = tmp_path / "short.csv"
    path.write_text(",".join(COLUMNS) + "\n" + ",".join(["0"] * 13) + "\n")
    with pytest.raises(TrajectoryError, match="line 2: expected 14 values"):
        Trajectory.read(path)
