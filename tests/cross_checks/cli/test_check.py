"""`rbcheck check` on random and damaged CSVs: exit 0, 1 or 2, never an exception, never a PASS on
non-finite data; exit 2 is one line on stderr naming the file."""
import os

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cross_checks.cli import main
from cross_checks.core.trajectory import COLUMNS, Trajectory, TrajectoryError
from cross_checks.engines import run_variant
from cross_checks.scenario import load_scenario

SCENARIO = "projectile"
GOOD = run_variant(load_scenario(SCENARIO), "reference:course", 0.05).to_csv_text()
TOKENS = ["nan", "inf", "-inf", "1e308", "-1e308", "0", "",
          "abc", "1e9", "-0.0", "1e-320", "0.05", "7", "1e30"]


@st.composite
def damaged_csv(draw):
    lines = GOOD.splitlines()
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["cell", "delete", "duplicate", "swap", "truncate", "insert", "header",
                                     "zero_q", "scale_t", "drop_column"]))
        if kind == "cell" and len(lines) > 1:
            i = draw(st.integers(1, len(lines) - 1))
            cells = lines[i].split(",")
            j = draw(st.integers(0, len(cells) - 1))
            cells[j] = draw(st.sampled_from(TOKENS))
            lines[i] = ",".join(cells)
        elif kind == "delete" and len(lines) > 1:
            del lines[draw(st.integers(0, len(lines) - 1))]
        elif kind == "duplicate" and len(lines) > 1:
            i = draw(st.integers(0, len(lines) - 1))
            lines.insert(i, lines[i])
        elif kind == "swap" and len(lines) > 2:
            i, j = draw(st.integers(1, len(lines) - 1)), draw(st.integers(1, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        elif kind == "truncate":
            text = "\n".join(lines)
            lines = text[:draw(st.integers(0, len(text)))].splitlines()
        elif kind == "insert":
            i = draw(st.integers(0, len(lines)))
            lines.insert(i, draw(st.text(max_size=20)))
        elif kind == "header" and lines:
            names = lines[0].split(",")
            a, b = draw(st.integers(0, len(names) - 1)), draw(st.integers(0, len(names) - 1))
            names[a], names[b] = names[b], names[a]
            lines[0] = ",".join(names)
        elif kind == "zero_q":
            for i in range(draw(st.integers(1, max(1, len(lines) - 1))), len(lines)):
                cells = lines[i].split(",")
                if len(cells) == len(COLUMNS):
                    cells[7:11] = ["0", "0", "0", "0"]
                    lines[i] = ",".join(cells)
        elif kind == "scale_t":
            factor = draw(st.sampled_from([1e9, 1e-9, -1.0, 0.5, 3.0]))
            for i in range(1, len(lines)):
                cells = lines[i].split(",")
                try:
                    cells[0] = repr(float(cells[0]) * factor)
                except ValueError:
                    pass
                lines[i] = ",".join(cells)
        elif kind == "drop_column" and lines:
            j = draw(st.integers(0, len(COLUMNS) - 1))
            lines = [",".join(c for k, c in enumerate(line.split(",")) if k != j) for line in lines]
    return "\n".join(lines) + "\n"


@settings(max_examples=int(os.environ.get("RBCHECK_FUZZ_EXAMPLES", 30)), deadline=None,
          derandomize=not os.environ.get("RBCHECK_FUZZ_EXAMPLES"),
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=damaged_csv())
def test_damaged_files_give_a_verdict_or_exit_2_never_an_exception(tmp_path, capsys, text):
    path = tmp_path / "fuzz.csv"
    path.write_bytes(text.encode("utf-8", errors="replace"))
    rc = main(["check", str(path), "--scenario", SCENARIO])
    out, err = capsys.readouterr()
    assert rc in (0, 1, 2)
    assert "Traceback" not in err
    if rc == 2:
        assert err.startswith("rbcheck check: error: ") and err.count("\n") == 1, err
        return
    assert out.startswith("PASS: ") if rc == 0 else out.startswith("FAIL: ")
    if rc == 0:   # a PASS never hides a NaN, an absurd value or a zero quaternion
        traj = Trajectory.read(path, require=())
        cols = [c for c in range(13) if not np.all(np.isnan(traj.y[:, c]))]
        assert np.all(np.isfinite(traj.y[:, cols]))
        if "orientation" in traj.meta["quantities_present"]:
            assert np.all(np.linalg.norm(traj.y[:, 6:10], axis=1) > 0.5)


def test_the_undamaged_file_passes(tmp_path, capsys):
    path = tmp_path / "good.csv"
    path.write_text(GOOD)
    assert main(["check", str(path), "--scenario", SCENARIO]) == 0
    assert capsys.readouterr().out.startswith("PASS: is reference:course")


def test_a_file_that_is_not_a_trajectory_exits_2(tmp_path, capsys):
    path = tmp_path / "bin.csv"
    path.write_bytes(b"\x00\xff\xfe garbage")
    assert main(["check", str(path), "--scenario", SCENARIO]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rbcheck check: error: {path}") and err.count("\n") == 1
    try:
        Trajectory.read(path)
    except TrajectoryError:
        pass
