"""reports.animation: frames sampled uniformly in time and few whatever the run's length; the box has the
body's principal moments; the report's animation data decodes to the series' orientations, and a run that
diverged stops at its divergence."""
import base64

import numpy as np
import pytest

from reports import animation as A
from reports.canvas import variant_styles
from reports.data import load_results
from tests.reports.test_polhode import tennis  # noqa: F401 - the shared tennis_racket results (fixture)


def test_a_long_run_gets_a_few_hundred_frames_uniform_in_time():
    t = np.arange(100_001) * 1e-4                       # 10 s at Δt = 1e-4 s
    k = A.frame_indices(t, A.MAX_FRAMES)
    assert 30 <= len(k) <= A.MAX_FRAMES <= 400
    assert k[0] == 0 and k[-1] == len(t) - 1
    gaps = np.diff(t[k])
    assert np.ptp(gaps) <= 1e-4 + 1e-12                  # uniform to one row
    short = np.arange(50) * 0.01
    assert list(A.frame_indices(short, A.MAX_FRAMES)) == list(range(50))


@pytest.mark.parametrize("moments", [(1.0, 2.0, 2.5), (0.4, 0.5, 0.6), (1.0, 1.0, 1.0)])
def test_the_box_has_the_bodys_principal_moments(moments):
    m = 2.0
    a, b, c = 2 * A.box_half_extents(moments, m)
    box = m / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    assert np.allclose(box, moments, rtol=1e-12)


def test_a_lamina_is_drawn_as_a_thin_plate():
    half = A.box_half_extents((1.0, 2.0, 3.0), 1.0)     # I1 + I2 = I3: zero thickness
    assert half[2] == pytest.approx(A.MIN_SIDE_FRACTION * half[0])


def _decode(b64, scale):
    v = np.frombuffer(base64.b64decode(b64), dtype="<i2").astype(float)
    return np.where(v == -32768, np.nan, v / scale)


def test_the_report_data_decodes_to_the_series_and_stays_small(tennis):  # noqa: F811
    res = load_results(tennis)
    data = A.report_animation(res, "tennis_racket", variant_styles(res.variants))
    n = len(data["t"])
    assert 30 <= n <= A.REPORT_FRAMES
    assert np.ptp(np.diff(data["t"])) < 1e-5                        # uniform in time
    ser = res.series("tennis_racket")
    runs = {r["name"]: r for r in data["runs"]}
    assert set(runs) == {"reference", *res.variants}
    for name in ("reference", "reference:rk4"):
        q = _decode(runs[name]["q"], 32767).reshape(n, 4)
        src = ser[name]
        k = np.searchsorted(src["t_s"], data["t"][-1])
        # the last frame is the series' last sample (sign-free: q and −q are one orientation)
        assert np.min([np.abs(q[-1] - src["q_WB"][k]).max(), np.abs(q[-1] + src["q_WB"][k]).max()]) < 1e-4
    err = _decode(runs["reference:course"]["err"], 100)
    assert err.max() > 30.0                     # the course's box ends far from the reference's (degrees)
    assert data["default"] == max((r for r in data["runs"][1:]), key=lambda r: r["final_err"])["name"]
    assert "frames, one every" in data["caption"]


def test_a_run_that_diverged_stops_at_its_divergence(tennis, monkeypatch):  # noqa: F811
    res = load_results(tennis)
    import reports.canvas
    monkeypatch.setattr(reports.canvas, "diverged_at", lambda r, s, v: 4.0 if v == "reference:rk4" else None)
    data = A.report_animation(res, "tennis_racket", variant_styles(res.variants))
    run = next(r for r in data["runs"] if r["name"] == "reference:rk4")
    q = _decode(run["q"], 32767).reshape(-1, 4)
    t = np.asarray(data["t"])
    assert run["div"] == 4.0
    assert np.all(np.isfinite(q[t <= 3.9])) and np.all(np.isnan(q[t > 4.1]))
    assert data["default"] != "reference:rk4"
