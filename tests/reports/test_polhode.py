"""reports.polhode: the closed-form polhodes lie on the sphere and the energy ellipsoid; the scenario
figure's data shows the course's step (no gyroscopic term) with ω fixed in body axes while the reference's
L flips; the figure is drawn on the scenario page and in `check --plot`."""
import dataclasses
import math

import numpy as np
import pytest

import reports
from cross_checks.engines import run_variant
from cross_checks.gates.check import check_trajectory
from cross_checks.scenario import load_scenario
from cross_checks.sweep import run_sweep
from reports import polhode as P
from reports.canvas import variant_styles
from reports.check_plot import check_figure
from reports.data import load_results
from tests.helpers import tolerances as tol
from tests.helpers.sweeps import built_once, private_cache

MOMENTS = (1.0, 2.0, 3.0)


@pytest.mark.parametrize("L0", [(0.01, 4.0, 0.03), (0.3, 0.2, 2.5), (0.9, 0.3, 0.1), (1.0, 0.0, 0.0)])
def test_every_curve_is_on_the_sphere_and_its_energy_ellipsoid(L0):
    L0 = np.asarray(L0, dtype=float)
    Lm = np.linalg.norm(L0)
    D0 = Lm ** 2 / np.sum(L0 ** 2 / np.asarray(MOMENTS))     # |L|²/2E of the given point
    curves = P.polhode_curves(MOMENTS, L0)
    kinds = [k for k, _ in curves]
    assert kinds.count("own") == 1 and kinds.count("separatrix") == 1
    for kind, c in curves:
        c = c[np.all(np.isfinite(c), axis=1)]
        assert np.allclose(np.linalg.norm(c, axis=1), 1.0, atol=tol.POLHODE_CLOSED_FORM)
        level = 1.0 / np.sum(c ** 2 / np.asarray(MOMENTS), axis=1)       # D along the curve
        assert np.ptp(level) <= tol.POLHODE_CLOSED_FORM * MOMENTS[2], kind
        if kind == "separatrix":
            assert np.allclose(level, MOMENTS[1], rtol=tol.POLHODE_CLOSED_FORM)
        if kind == "own":
            assert np.allclose(level, D0, rtol=tol.POLHODE_CLOSED_FORM)
            # the curve passes through the point (at the closed form's sampling: 241 points per loop)
            assert np.min(np.linalg.norm(c - L0 / Lm, axis=1)) < 0.03


def test_an_isotropic_body_has_no_polhodes():
    assert P.polhode_curves((2.0, 2.0, 2.0), (0.1, 0.2, 0.3)) == []


def test_the_momentum_in_principal_axes_is_rotation_invariant():
    """L in principal axes of a body whose inertia is not diagonal in its body axes: |L| and E as in world."""
    rng = np.random.default_rng(3)
    A = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    inertia_B = A @ np.diag(MOMENTS) @ A.T
    q = rng.normal(size=(5, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w_W = rng.normal(size=(5, 3))
    L_P = P.momentum_principal(q, w_W, inertia_B)
    from reference_sim.quaternion import matrix_from_quat
    R = matrix_from_quat(q)
    L_W = np.einsum("nij,jk,nlk,nl->ni", R, inertia_B, R, w_W)
    assert np.allclose(np.linalg.norm(L_P, axis=1), np.linalg.norm(L_W, axis=1), rtol=1e-12)
    E = 0.5 * np.sum(w_W * L_W, axis=1)
    assert np.allclose(0.5 * np.sum(L_P ** 2 / np.asarray(MOMENTS), axis=1), E, rtol=1e-12)


def _tennis_sweep(folder):
    sc = dataclasses.replace(load_scenario("tennis_racket"), dt_ladder_s=(0.01, 0.005, 0.0025))
    with private_cache(folder / "cache"):
        run_sweep([sc], ["reference:course", "reference:rk4", "mujoco:euler"], folder / "res", jobs=1,
                  finish=lambda d: reports.render(d, progress=False))


@pytest.fixture(scope="module")
def tennis(tmp_path_factory):
    return built_once(tmp_path_factory, "polhode_tennis", _tennis_sweep) / "res"


def _drawn(fig, gid):
    """The projected points of the path ``gid`` drawn in ``fig`` (front and back halves)."""
    pts = [np.column_stack(line.get_data()) for ax in fig.axes for line in ax.get_lines()
           if line.get_gid() in (gid, gid + " (back)")]
    xy = np.concatenate(pts)
    return xy[np.all(np.isfinite(xy), axis=1)]


def test_the_course_step_sits_still_in_body_axes_while_the_reference_flips(tennis):
    res = load_results(tennis)
    fig = P.polhode_figure(res, "tennis_racket", variant_styles(res.variants))
    key = ("scenario", "tennis_racket")
    ref, course = P.PATHS[(key, "reference")], P.PATHS[(key, "reference:course")]
    rk4 = P.PATHS[(key, "reference:rk4")]
    # the reference's L goes from +e2 to −e2 (the flip): its direction turns by ~π in body axes
    assert P.spread_rad(ref) > math.pi - 0.2
    assert ref[0, 1] > 0.99 and ref[:, 1].min() < -0.99
    # the course's ω stays fixed in body axes: its L turns by round-off only (float32 series)
    assert P.spread_rad(course) < tol.POLHODE_FIXED_RAD
    # a correct scheme flips like the reference
    assert P.spread_rad(rk4) > math.pi - 0.2
    # on the figure itself: the course's drawn points sit on one spot, the reference's span the sphere
    spot, flip = _drawn(fig, "reference:course"), _drawn(fig, "reference")
    assert np.ptp(spot, axis=0).max() < tol.POLHODE_FIXED_RAD and np.ptp(flip, axis=0).max() > 1.0
    assert "for: reference:course:" in reports.canvas.NOTES.pop(("tennis_racket", "polhode"))


def test_the_scenario_page_shows_the_polhode_and_says_which_run_sits_still(tennis):
    html = (tennis / "scenario-tennis_racket.html").read_text(encoding="utf-8")
    assert 'src="plots/tennis_racket__polhode.png"' in html
    assert "Polhode (L in body axes)" in html
    assert "stays fixed (within 5 % of that) for: reference:course" in html
    from matplotlib.image import imread
    img = imread(tennis / "plots" / "tennis_racket__polhode.png")
    assert img.shape[1] >= 1100 and np.std(img) > 0.05


def test_check_plot_has_the_polhode_of_the_file(tmp_path):
    sc = load_scenario("tennis_racket")
    tr = run_variant(sc, "reference:course", 0.005, sc.duration_s)
    res = check_trajectory(tr, sc, "course.csv")
    check_figure(res, sc, tmp_path / "c.png")
    assert P.spread_rad(P.PATHS[(("check", "course.csv"), "file")]) < tol.POLHODE_FIXED_RAD
    assert P.spread_rad(P.PATHS[(("check", "course.csv"), "reference")]) > math.pi - 0.2
    from PIL import Image
    with Image.open(tmp_path / "c.png") as im:
        assert im.size == (1800, 880)


def test_the_sweep_saves_what_the_polhode_needs(tennis):
    """series/<scenario>.npz carries ω in world axes for the reference and every variant, and summary.json the
    body (docs/results.md): the report draws the polhode from them without running anything."""
    res = load_results(tennis)
    info = res.scenario("tennis_racket")
    assert info["inertia_B_kg_m2"] == [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]]
    assert info["mass_kg"] == 1.0
    ser = res.series("tennis_racket")
    for who in ("reference", *res.variants):
        assert ser[who]["w_W"].shape == (len(ser[who]["t_s"]), 3)
    assert np.allclose(ser["reference"]["w_W"][0], [0.01, 2.0, 0.01], rtol=1e-6)


def test_results_written_before_the_polhode_say_so_instead(tennis, tmp_path):
    """A results directory without ω in its series nor the body in summary.json (an older rbcheck's): the page
    says why there is no polhode, and has no animation; nothing fails."""
    import json
    import shutil
    d = tmp_path / "res"
    shutil.copytree(tennis, d)
    npz = d / "series" / "tennis_racket.npz"
    with np.load(npz) as z:
        kept = {k: z[k] for k in z.files if not k.endswith("::w_W")}
    np.savez(npz, **kept)
    s = json.loads((d / "summary.json").read_text())
    for sc in s["scenarios"]:
        sc.pop("inertia_B_kg_m2"), sc.pop("mass_kg")
    (d / "summary.json").write_text(json.dumps(s))
    reports.render(d, progress=False)
    html = (d / "scenario-tennis_racket.html").read_text(encoding="utf-8")
    assert "Polhode (L in body axes): no angular velocity in the saved series" in html
    assert 'id="anim-data"' not in html and not (d / "plots" / "tennis_racket__polhode.png").exists()
