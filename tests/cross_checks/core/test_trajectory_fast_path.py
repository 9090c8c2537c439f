"""The trajectory reader's fast path (plain numeric CSVs, e.g. an engine's 40 000 rows) gives exactly what
the general csv.reader path gives — the same numbers, or the same error message — on any text."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cross_checks.core.trajectory import COLUMNS, TrajectoryError, read_columns

CELLS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(-1e3, 1e3).map(lambda v: f"{v:.6f}"),
    st.sampled_from(["", " ", " 1.5", "1.5 ", "\t2", "nan", "-inf", "Infinity", "1_0", "0x10", "1e500", "+1",
                     ".5", "5.", "1e-400", "NaN", "1e", "abc", '"3"', "١", "\u00a01", "1,5", "\x00"]),
)


@st.composite
def csv_texts(draw):
    header = draw(st.permutations(list(COLUMNS) + ["extra"]))[: draw(st.integers(13, 15))]
    n = draw(st.integers(0, 6))
    lines = [",".join(header)]
    for k in range(n):
        cells = [repr(0.01 * k) if h == "t" else draw(CELLS) if draw(st.integers(0, 9)) == 0 else repr(draw(
            st.floats(-10, 10))) for h in header]
        if draw(st.integers(0, 12)) == 0:
            cells = cells[:-1]
        lines.append(",".join(cells))
        if draw(st.integers(0, 12)) == 0:
            lines.append(draw(st.sampled_from(["", "   ", ",", " , "])))
    return "\n".join(lines) + draw(st.sampled_from(["", "\n", "\n\n"]))


def _read(path, fast):
    try:
        t, y, present = read_columns(path, require=(), _fast=fast)
        return ("ok", t.tobytes(), np.nan_to_num(y, nan=1234.5).tobytes(), present)
    except TrajectoryError as exc:
        return ("error", str(exc))


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=csv_texts())
def test_fast_path_reads_exactly_what_the_general_path_reads(tmp_path, text):
    path = tmp_path / "t.csv"
    path.write_text(text, encoding="utf-8")
    assert _read(path, True) == _read(path, False)


def test_nul_bytes_are_a_trajectory_error_not_a_crash(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text(",".join(COLUMNS) + "\n" + ",".join(["0"] * 13) + ",\x00\n")
    with pytest.raises(TrajectoryError, match="t.csv: "):
        read_columns(path)
