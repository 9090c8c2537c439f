"""The polhode: the path of the angular momentum L in the body's principal axes, on the sphere |L| = const,
beside the closed-form intersection curves of that sphere with the energy ellipsoid (the polhodes).

A torque-free body keeps E and |L|, so its L, seen from the body, stays on one polhode: a pure spin about
the major or minor axis sits still, the tennis racket's L runs along the curve next to the separatrix from
+e₂ to −e₂ and back (the flip). A step that rescales |L| or pumps E slides from one curve to the next; a step
without the gyroscopic term (the course's) keeps ω fixed in world axes, so the body spins about a fixed
axis and its L, seen from the body, sits still where the reference's flips.

The curves come from the closed form of sphere ∩ ellipsoid (:func:`polhode_curves`), never from an
integration. Drawn, in the report's styles (reports.canvas.variant_styles), on each scenario page
(:func:`fig_polhode`: the reference and one panel per engine family), on integrators.html for the long runs
(:func:`fig_long_polhode`) and in ``rbcheck check --plot`` (:func:`polhode_panel`). Every drawn path is an
artist whose gid is its owner ("reference", "ENGINE:VARIANT", "file"), its 3-D points (unit sphere =
the reference's |L₀|) in ``PATHS`` by (figure key, owner): what the tests read.
"""
from __future__ import annotations

import math

import numpy as np

from reference_sim.quaternion import matrix_from_quat

__all__ = ["principal_frame", "momentum_principal", "body_to_principal", "polhode_curves", "project",
           "polhode_panel", "fig_polhode", "polhode_figure", "spread_rad", "fig_long_polhode",
           "long_run_columns", "rotating", "PATHS", "VIEW", "KIND", "draw", "camera",
           "relative_cost"]

#: The viewing direction of every polhode panel (elevation, azimuth, degrees): from above the major axis e₃,
#: tilted towards e₁, so that the intermediate axis ±e₂ sits near the outline and a flip +e₂ → −e₂ crosses
#: the front of the sphere on either side of e₃.
VIEW = (55.0, 15.0)
#: The drawn 3-D paths, by (figure key, owner): the figure's data, read by the tests.
PATHS: dict = {}
_AXIS_COLOURS = ("#d62728", "#2ca02c", "#1f77b4")   # e₁ (minor), e₂ (intermediate), e₃ (major)
_AXIS_NAMES = ("minor", "intermediate", "major")
#: A path whose direction moves less than this (rad) over the run, where the reference's moves more than 10
#: times as much, is marked "fixed" (★): a spin about an axis fixed in the body.
STILL_RAD = 0.02


def principal_frame(inertia_B) -> tuple:
    """``(moments, axes_B)``: the principal moments, ascending (kg m²), and the principal axes as the columns
    of a right-handed rotation (body axes)."""
    inertia_B = np.asarray(inertia_B, dtype=float)
    moments, axes = np.linalg.eigh(0.5 * (inertia_B + inertia_B.T))
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    return moments, axes


def momentum_principal(q_WB, w_W, inertia_B):
    """The angular momentum about the COM in the principal axes (N m s, (n, 3)) of orientations ``q_WB``
    (n, 4; w, x, y, z; normalised here) and angular velocities ``w_W`` (n, 3; rad/s, world axes)."""
    q = np.asarray(q_WB, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    R = matrix_from_quat(q)
    w_B = np.einsum("nji,nj->ni", R, np.asarray(w_W, dtype=float))
    return body_to_principal(w_B @ np.asarray(inertia_B, dtype=float).T, inertia_B)


def body_to_principal(L_B, inertia_B):
    """Body-axes vectors ``L_B`` (n, 3) in the principal axes of ``inertia_B`` (same units)."""
    return np.asarray(L_B, dtype=float) @ principal_frame(inertia_B)[1]


def _points(L_P) -> bool:
    return L_P is not None and len(L_P) > 0 and bool(np.all(np.isfinite(L_P[0])))


def polhode_curves(moments, L0_P, n: int = 241) -> list:
    """The polhodes on the unit sphere (= |L₀|) of a body of principal ``moments`` (ascending), from the
    closed form of sphere ∩ energy ellipsoid: ``[(kind, points (m, 3))]``, kind "own" (the curve through
    ``L0_P``: its E and |L|), "separatrix" (2E = |L|²/I₂, two great circles) or "other" (a family of
    levels for context). Each curve is a closed loop (or two, one per side); NaN rows separate loops.
    An isotropic body has no curves (every direction is a fixed point): []."""
    I1, I2, I3 = (float(m) for m in moments)
    L0 = np.asarray(L0_P, dtype=float)
    Lm = float(np.linalg.norm(L0))
    if not (Lm > 0 and math.isfinite(Lm)) or I3 - I1 <= 1e-12 * I3:
        return []
    D0 = Lm ** 2 / float(np.sum(L0 ** 2 / np.asarray(moments, dtype=float)))   # |L|²/2E, in [I1, I3]
    out = []
    levels = [I1 + (I2 - I1) * f for f in (0.25, 0.55, 0.8)] + [I2 + (I3 - I2) * f for f in (0.2, 0.45, 0.75)]
    for D in levels:
        c = _level_curve((I1, I2, I3), D, n)
        if c is not None:
            out.append(("other", c))
    sep = _level_curve((I1, I2, I3), I2, n)
    if sep is not None:
        out.append(("separatrix", sep))
    own = _level_curve((I1, I2, I3), min(max(D0, I1), I3), n, through=L0 / Lm)
    if own is not None:
        out.append(("own", own))
    return out


def _level_curve(moments, D, n, through=None):
    """The curve(s) of the unit sphere where Σ L_i²/I_i = 1/D (D = |L|²/2E): a_i L_i² sum to 0 with
    a_i = 1/I_i − 1/D. The axis k whose a_k has the other sign is the one the curves circle:
    L_i = ρ cos φ/√|a_i|, L_j = ρ sin φ/√|a_j|, L_k = ±ρ/√|a_k|, ρ = (cos²φ/|a_i| + sin²φ/|a_j| + 1/|a_k|)^−½.
    ``through``: keep only the loop on that point's side (its own polhode)."""
    m = np.asarray(moments, dtype=float)
    a = 1.0 / m - 1.0 / D
    scale = float(np.max(np.abs(a))) or 1.0
    zero = np.abs(a) <= 1e-9 * scale
    phi = np.linspace(0.0, 2.0 * math.pi, n)
    gap = np.full((1, 3), np.nan)
    if zero.sum() >= 2:    # two equal moments at this level: a great circle in their plane
        i, j = np.flatnonzero(zero)[:2]
        c = np.zeros((n, 3))
        c[:, i], c[:, j] = np.cos(phi), np.sin(phi)
        return c
    if zero.sum() == 1:
        z = int(np.flatnonzero(zero)[0])
        others = [x for x in range(3) if x != z]
        if np.sign(a[others[0]]) == np.sign(a[others[1]]):   # a pure spin about axis z: two points
            pts = np.zeros((2, 3))
            pts[0, z], pts[1, z] = 1.0, -1.0
            if through is not None:
                return pts[[0]] if through[z] >= 0 else pts[[1]]
            return np.vstack([pts[[0]], gap, pts[[1]]])
        # the separatrix: the planes √|a_p| L_p = ±√|a_q| L_q through axis z, two great circles
        p, q = others
        loops = []
        for s in (1.0, -1.0):
            u = np.zeros(3)
            u[p], u[q] = math.sqrt(abs(a[q])), s * math.sqrt(abs(a[p]))
            u /= np.linalg.norm(u)
            e = np.zeros(3)
            e[z] = 1.0
            loops.append(np.outer(np.cos(phi), u) + np.outer(np.sin(phi), e))
        return np.vstack([loops[0], gap, loops[1]])
    signs = np.sign(a)
    k = next(x for x in range(3) if (signs == signs[x]).sum() == 1)
    i, j = [x for x in range(3) if x != k]
    w = np.cos(phi) ** 2 / abs(a[i]) + np.sin(phi) ** 2 / abs(a[j]) + 1.0 / abs(a[k])
    rho = 1.0 / np.sqrt(w)
    loops = []
    for s in (1.0, -1.0):
        c = np.zeros((n, 3))
        c[:, i] = rho * np.cos(phi) / math.sqrt(abs(a[i]))
        c[:, j] = rho * np.sin(phi) / math.sqrt(abs(a[j]))
        c[:, k] = s * rho / math.sqrt(abs(a[k]))
        loops.append(c)
    if through is not None:
        return loops[0] if through[k] >= 0 else loops[1]
    return np.vstack([loops[0], gap, loops[1]])


def camera(view=VIEW):
    el, az = (math.radians(v) for v in view)
    right = np.array([-math.sin(az), math.cos(az), 0.0])
    up = np.array([-math.sin(el) * math.cos(az), -math.sin(el) * math.sin(az), math.cos(el)])
    toward = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    return right, up, toward


def project(P, view=VIEW) -> tuple:
    """Orthographic projection of 3-D points ``P`` (n, 3): ``(x, y, depth)``, depth > 0 towards the viewer."""
    right, up, toward = camera(view)
    P = np.asarray(P, dtype=float)
    return P @ right, P @ up, P @ toward


def _split(P, view=VIEW, at=(0.0, 0.0)) -> tuple:
    """(front xy, back xy) of a path, shifted by ``at``: each an (n, 2) array with NaN where the other side
    is."""
    x, y, d = project(P, view)
    x, y = x + at[0], y + at[1]
    front = np.where((d >= 0)[:, None], np.column_stack([x, y]), np.nan)
    back = np.where((d < 0)[:, None], np.column_stack([x, y]), np.nan)
    return front, back


def _line(ax, x, y, **style):
    """One Line2D added to ``ax`` as it is (no autoscaling: the panels have fixed limits)."""
    from matplotlib.lines import Line2D
    return ax.add_line(Line2D(np.asarray(x, dtype=float), np.asarray(y, dtype=float), **style))


def _joined(parts) -> np.ndarray:
    """(n, 2) arrays joined into one, NaN rows between them: one artist for many curves."""
    gap = np.full((1, 2), np.nan)
    return np.concatenate([x for p in parts for x in (p, gap)]) if parts else np.zeros((0, 2))


_CURVE_STYLE = {"own": ("#222222", 1.3, "-"), "separatrix": ("#7f7f7f", 1.0, "--"),
                "other": ("#b0b0b0", 0.7, "-")}


def _sphere(ax, curves, moments, axis_labels=True, fontsize=7.5, at=(0.0, 0.0), frame=True) -> None:
    """The unit sphere's outline, the polhodes (back half faint) and the principal axes, centred at ``at``
    (data units); one artist per kind of curve and side (the report draws many panels). ``frame``: the
    axes are this panel's own (limits ±1.3, equal aspect, no axis lines)."""
    from reports.canvas import DataStamps
    t = np.linspace(0, 2 * math.pi, 181)
    _line(ax, np.cos(t) + at[0], np.sin(t) + at[1], color="#888888", lw=0.8)
    for kind, (colour, lw, ls) in _CURVE_STYLE.items():
        sides = [_split(c, at=at) for k, c in curves if k == kind]
        if not sides:
            continue
        f, b = _joined([f for f, _ in sides]), _joined([b for _, b in sides])
        _line(ax, f[:, 0], f[:, 1], color=colour, lw=lw, ls=ls, zorder=1.5)
        _line(ax, b[:, 0], b[:, 1], color=colour, lw=lw * 0.8, ls=":", alpha=0.45, zorder=1.2)
    labels = []
    for i in range(3):
        e = np.zeros((2, 3))
        e[1, i] = 1.18
        x, y, d = project(e)
        _line(ax, x + at[0], y + at[1], color=_AXIS_COLOURS[i], lw=1.0, alpha=0.9 if d[1] >= 0 else 0.45,
              zorder=1.1)
        if axis_labels:
            labels.append((x[1] * 1.07 + at[0], y[1] * 1.07 + at[1], f"e{i + 1}", fontsize,
                           {"ha": "center", "va": "center", "color": _AXIS_COLOURS[i]}))
    if labels:
        ax.add_artist(DataStamps(labels))
    if frame:
        ax.set_xlim(-1.3, 1.3)
        ax.set_ylim(-1.3, 1.3)
        ax.set_aspect("equal")
        ax.set_axis_off()


def _path(ax, P, gid, color, ls="-", lw=1.2, alpha=1.0, zorder=2.0, key=None, at=(0.0, 0.0)) -> None:
    """A 3-D path (unit sphere = |L₀|) drawn front solid, back faint; its points kept in PATHS[key, gid]."""
    f, b = _split(P, at=at)
    _line(ax, f[:, 0], f[:, 1], color=color, ls=ls, lw=lw, alpha=alpha, zorder=zorder, gid=gid)
    _line(ax, b[:, 0], b[:, 1], color=color, ls=ls, lw=lw * 0.8, alpha=alpha * 0.35, zorder=zorder - 0.5,
          gid=gid + " (back)")
    if key is not None:
        PATHS[(key, gid)] = np.asarray(P, dtype=float)


def _start_end(ax, P, color, at=(0.0, 0.0)) -> None:
    ok = np.flatnonzero(np.all(np.isfinite(P), axis=1))
    if not ok.size:
        return
    for k, marker in ((ok[0], "o"), (ok[-1], "s")):
        x, y, d = project(P[[k]])
        _line(ax, x + at[0], y + at[1], marker=marker, ms=4.5, color=color, mec="black", mew=0.6, ls="none",
              zorder=3, alpha=1.0 if d[0] >= 0 else 0.5)


def rotating(L_P_ref) -> bool:
    """Whether the reference rotates (|L| not zero at the start): a polhode to draw."""
    return _points(L_P_ref) and float(np.linalg.norm(L_P_ref[0])) > 0.0


def polhode_panel(ax, moments, paths, torque_free: bool, title: str = "", key=None, at=(0.0, 0.0),
                  frame=True) -> None:
    """One polhode panel on ``ax``, centred at ``at`` (data units; ``frame``: the axes are the panel's own):
    ``paths`` [(gid, L_P (n, 3) N m s, style dict: color, ls, lw, alpha)], the first one the reference (its
    first sample sets |L₀| and the curves). A path that is not torque-free is drawn as L's direction (|L|
    changes along it) without curves."""
    ref = paths[0][1]
    Lm = float(np.linalg.norm(ref[0]))
    curves = polhode_curves(moments, ref[0]) if torque_free else []
    _sphere(ax, curves, moments, at=at, frame=frame)
    moves = spread_rad(ref) > STILL_RAD * 10
    still = []
    for gid, L, st in paths:
        L = np.asarray(L, dtype=float)
        P = L / Lm if torque_free else L / np.linalg.norm(L, axis=1, keepdims=True)
        _path(ax, P, gid, st.get("color", "black"), st.get("ls", "-"), st.get("lw", 1.2),
              st.get("alpha", 1.0), st.get("zorder", 2.0), key, at)
        if st.get("ends", True):
            _start_end(ax, P, st.get("color", "black"), at)
        if moves and gid != paths[0][0] and spread_rad(L) < STILL_RAD:
            still.append((gid, P, st.get("color", "black")))
    for k, (gid, P, colour) in enumerate(still):   # a path that sits still is a point: say so beside it
        x, y, _ = project(P[[0]])
        x, y = x + at[0], y + at[1]
        _line(ax, x, y, marker="*", ms=11, color=colour, mec="black", mew=0.7, ls="none", zorder=3.5)
        ax.annotate(f"★ {gid.split(':', 1)[-1]}: fixed", (x[0], y[0]), xytext=(-4, -13 - 10 * k),
                    textcoords="offset points", ha="right", fontsize=7, color="black", zorder=3.5)
    if title:
        from reports.canvas import DataStamps
        ax.add_artist(DataStamps([(at[0], at[1] + 1.36, title, 9, {"ha": "center", "va": "baseline"})]))


# --- the scenario page --------------------------------------------------------------------------------

def _body(info):
    I = info.get("inertia_B_kg_m2")
    return None if I is None else np.asarray(I, dtype=float)


def scenario_paths(res, sc) -> dict:
    """``{owner: L in principal axes (n, 3), N m s}`` of the scenario's saved series (the reference and
    every variant with ``w_W``), each run that diverged cut at its divergence; {} without the body or ω."""
    from reports.canvas import diverged_at
    info = res.scenario(sc)
    inertia = _body(info)
    ser = res.series(sc)
    if inertia is None or "reference" not in ser or "w_W" not in ser["reference"]:
        return {}
    out = {}
    for who, f in ser.items():
        if "w_W" not in f or "q_WB" not in f:
            continue
        L = momentum_principal(f["q_WB"], f["w_W"], inertia)
        tdiv = None if who == "reference" else diverged_at(res, sc, who)
        if tdiv is not None:
            L = np.where((f["t_s"] <= tdiv)[:, None], L, np.nan)
        out[who] = L
    return out


def _torque_free(info) -> bool:
    """No torque about the COM and no angular decay (L conserved): then the rotational energy is conserved
    too (gravity and forces through the COM leave both alone), and the polhodes apply."""
    return bool(info.get("conserved", {}).get("angular_momentum", {}).get("conserved"))


#: The figure's kind in the report's task list (reports.render draws it beside reports.plots.KINDS).
KIND = "polhode"


def draw(res, sc, plot_dir) -> tuple:
    """Draw the scenario's polhode into ``plot_dir``, as reports.plots.draw draws its figures; returns
    ``(KIND, filename or None, note)``."""
    from cross_checks.sweep.results_dir import inside
    from reports.canvas import NOTES, figure_name, variant_styles
    name = figure_name(sc, KIND)
    ok = fig_polhode(res, sc, variant_styles(res.variants), inside(plot_dir, name))
    return KIND, (name if ok else None), NOTES.pop((sc, KIND), "")


def relative_cost(res, sc) -> float:
    """The figure's drawing cost in reports.plots.relative_cost's units (a trajectories panel = 1): one
    panel per engine family and the reference's, each ~3 (measured), ~0 when the body does not turn."""
    from reports.glance import families
    varies = res.scenario(sc).get("varies", {}).get("orientation", True)
    n = len(families(res.variants)) + 1
    return (3.0 if varies else 0.1) * n * (1 + 0.1 * len(res.variants))


def fig_polhode(res, sc, styles, path) -> bool:
    """Draw :func:`polhode_figure` to ``path``; False (a note instead) when nothing rotates."""
    from reports.canvas import save_png
    fig = polhode_figure(res, sc, styles)
    if fig is None:
        return False
    save_png(fig, path)
    return True


def polhode_figure(res, sc, styles):
    """The scenario's polhode figure: the reference alone, then one panel per engine family (its variants in
    their styles over the reference's path in thick grey); None (a note instead) when nothing rotates."""
    from reports.canvas import MAX_COLUMNS, NOTES, REPORT_DPI, figure_legend, legend_entries, new_figure
    from reports.glance import families
    info = res.scenario(sc)
    paths = scenario_paths(res, sc)
    if not paths:
        NOTES[(sc, "polhode")] = ("no angular velocity in the saved series (results written before the "
                                  "polhode existed: run the sweep again)" if _body(info) is not None
                                  or "reference" in res.series(sc) else "no series")
        return None
    ref = paths["reference"]
    if not rotating(ref):
        NOTES[(sc, "polhode")] = "the body does not rotate"
        return None
    moments = principal_frame(_body(info))[0]
    free = _torque_free(info)
    fams = {f: [v for v in vs if v in paths] for f, vs in families(res.variants).items()}
    fams = {f: vs for f, vs in fams.items() if vs}
    n = 1 + len(fams)
    cols = min(n, MAX_COLUMNS)
    rows = math.ceil(n / cols)
    w_in = 13.0
    cell = w_in / cols
    fig = new_figure((w_in, 4.0), dpi=REPORT_DPI)
    leg_in = figure_legend(fig, w_in, legend_entries(fams, styles, markers=False))   # the report's legends
    title_in, head_in = 0.5, 0.3
    h_in = title_in + rows * (cell + head_in) + leg_in + 0.15
    fig.set_size_inches(w_in, h_in)
    # one axes for every panel (an axes each costs more to draw than its curves): a data unit is the same
    # length in x and y, a sphere of radius 1 fills its cell (±1.3 across cell − 0.1 in)
    unit = (cell - 0.1) / 2.6
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0.0, w_in / unit)
    ax.set_ylim(0.0, h_in / unit)
    ax.set_axis_off()

    def centre(k):
        r, c = divmod(k, cols)
        return ((c + 0.5) * cell / unit, (h_in - title_in - head_in - r * (cell + head_in) - cell / 2) / unit)
    key = ("scenario", sc)
    grey = {"color": "#000000", "lw": 3.0, "alpha": 0.22, "ends": False, "zorder": 1.8}
    polhode_panel(ax, moments, [("reference", ref, {"color": "#333333", "lw": 1.4})], free,
                  f"reference solution ({info['reference'].split(' (')[0]})", key=key, at=centre(0),
                  frame=False)
    for k, (fam, vs) in enumerate(fams.items(), start=1):
        polhode_panel(ax, moments, [("reference", ref, grey)]
                      + [(v, paths[v], {**styles[v], "lw": 1.1}) for v in vs], free, fam, key=key,
                      at=centre(k), frame=False)
    what = ("L in the principal axes on the sphere |L| = |L₀| with the polhodes for the reference's E and |L|"
            if free else "the direction of L in the principal axes (the torque changes E and |L|: no "
                         "polhodes)")
    fig.suptitle(f"{sc}: polhode at Δt = {info['dt_s']:g} s: {what}", x=0.01, ha="left", fontsize=10)
    NOTES[(sc, "polhode")] = _note(paths, res, sc, free)
    return fig


def spread_rad(L_P) -> float:
    """The largest angle (rad) between L's direction at any sample and at the first: 0 for L fixed in body
    axes, π for a flip."""
    L = np.asarray(L_P, dtype=float)
    L = L[np.all(np.isfinite(L), axis=1)]
    if len(L) < 2:
        return 0.0
    u = L / np.linalg.norm(L, axis=1, keepdims=True)
    return float(np.max(np.arctan2(np.linalg.norm(np.cross(u, u[0]), axis=1), u @ u[0])))


def _note(paths, res, sc, free) -> str:
    """The caption's sentence on what the paths do: which stay fixed in body axes where the reference
    moves."""
    ref = spread_rad(paths["reference"])
    still = [v for v, L in paths.items() if v != "reference" and spread_rad(L) < 0.05 * max(ref, 1e-12)]
    if ref > 0.5 and still:
        return (f"L moves over {math.degrees(ref):.0f}° in body axes along the reference, but stays fixed "
                f"(within 5 % of that) for: {', '.join(still)}: no gyroscopic term, so ω is fixed in world "
                "axes and the body spins about it.")
    return ""


# --- the integrators page: the long runs --------------------------------------------------------------

#: The long-run verdicts in a panel's title (reports.integrators.VERDICT_WORDS says them in full).
_SHORT_VERDICT = {"none": "δ kept", "toward_intermediate": "δ → 0 (toward e2)",
                  "away_from_intermediate": "|δ| grows (away from e2)",
                  "crosses_separatrix": "crosses the separatrix",
                  "diverged": "diverged", "failed": "failed"}


def long_run_columns(view) -> list:
    """The columns of the long runs' polhode figure: ``[(variant shown, [variants with the same verdicts])]``:
    the variant that keeps best (the first ranked), then, for each distinct pattern of verdicts over the long
    runs with a drift of δ in it, the best-ranked variant of that pattern (the others named under it)."""
    drifts = ("toward_intermediate", "away_from_intermediate", "crosses_separatrix")
    names = view.long_runs
    groups: dict = {}
    keeper = None
    for s in view.long:
        pattern = tuple(s.records.get(n, {}).get("verdict") for n in names)
        if keeper is None and s.score is not None and math.isfinite(s.score) and not any(
                v in drifts for v in pattern):
            keeper = s.variant
        if any(v in drifts for v in pattern):
            groups.setdefault(pattern, []).append(s.variant)
    out = [(keeper, [])] if keeper else []
    return out + [(vs[0], vs[1:]) for vs in groups.values()]


def fig_long_polhode(res, view, path) -> bool:
    """One row per long run: the polhode of the variant that keeps best, then of one variant per pattern of
    drifts (samples coloured by time, early dark to late light: a slide from curve to curve shows; the
    variants with the same verdicts named under the column). False when the long runs' series have no L_B
    (results written before it existed) or nothing ran."""
    import textwrap

    import matplotlib
    from matplotlib import cm

    from reports.canvas import REPORT_DPI, new_figure, save_png
    names = view.long_runs
    recs = {x["name"]: x for x in res.summary.get("long_run_scenarios") or []}
    columns = long_run_columns(view)
    if not columns or not names:
        return False
    got = {n: res.series(n) for n in names}
    if not any("L_B" in f for ser in got.values() for f in ser.values()):
        return False
    cols = len(columns)
    cell = min(2.3, 12.8 / cols)
    also = [textwrap.wrap("same: " + ", ".join(more), 30, break_long_words=False, break_on_hyphens=False)
            if more else [] for _, more in columns]
    also_in = 0.14 * max((len(a) for a in also), default=0) + 0.1
    w_in = cell * cols + 0.4
    top_in, bar_in, head_in = 0.45, 0.75, 0.42
    h_in = top_in + (cell + head_in) * len(names) + also_in + bar_in
    fig = new_figure((w_in, h_in), dpi=REPORT_DPI)
    cmap = matplotlib.colormaps["viridis"]
    for r, name in enumerate(names):
        inertia = recs.get(name, {}).get("inertia_B_kg_m2")
        ser = got[name]
        y0 = h_in - top_in - (r + 1) * (cell + head_in)
        for c, (v, _) in enumerate(columns):
            ax = fig.add_axes(((0.35 + c * cell + 0.04) / w_in, y0 / h_in, (cell - 0.08) / w_in, cell / h_in))
            d = ser.get(v)
            rec = next((s.records.get(name) for s in view.long if s.variant == v), None) or {}
            L = None if inertia is None or not d or "L_B" not in d else body_to_principal(d["L_B"], inertia)
            ok = np.zeros(0, dtype=bool) if L is None else np.all(np.isfinite(L), axis=1)
            if L is not None and rec.get("status") == "diverged" and rec.get("diverged_at_s") is not None:
                ok &= d["t_s"] <= rec["diverged_at_s"]
            if L is None or not ok.any():
                ax.set_axis_off()
                ax.text(0.5, 0.5, "no data" if L is None else "no finite sample", ha="center",
                        transform=ax.transAxes, fontsize=8)
                continue
            moments = principal_frame(inertia)[0]
            L0 = L[np.flatnonzero(ok)[0]]
            _sphere(ax, polhode_curves(moments, L0), moments, axis_labels=(c == 0), fontsize=7)
            P = L[ok] / np.linalg.norm(L0)
            x, y, dep = project(P)
            tt = d["t_s"][ok] / max(float(d["t_s"][-1]), 1e-300)
            front = dep >= 0
            ax.scatter(x[~front], y[~front], c=tt[~front], cmap=cmap, vmin=0, vmax=1, s=3, alpha=0.3,
                       linewidths=0, zorder=2)
            ax.scatter(x[front], y[front], c=tt[front], cmap=cmap, vmin=0, vmax=1, s=4, linewidths=0,
                       zorder=2.5, gid=v)
            PATHS[(("long", name), v)] = P
            verdict = rec.get("verdict", "")
            ax.set_title((f"{v}\n" if r == 0 else "") + _SHORT_VERDICT.get(verdict, str(verdict)),
                         fontsize=7.5)
        fig.text(0.3 / w_in, (y0 + cell / 2) / h_in, name, rotation=90, ha="right", va="center", fontsize=8.5,
                 weight="bold")
    for c, lines in enumerate(also):
        if lines:
            fig.text((0.35 + (c + 0.5) * cell) / w_in, (bar_in + also_in - 0.05) / h_in, "\n".join(lines),
                     ha="center", va="top", fontsize=6.5, color="#444444")
    sm = cm.ScalarMappable(cmap=cmap, norm=matplotlib.colors.Normalize(0, 1))
    cax = fig.add_axes((0.3, 0.45 / h_in, 0.4, 0.12 / h_in))
    cb = fig.colorbar(sm, cax=cax, orientation="horizontal")
    cb.set_label("time / run length (≤ 500 samples evenly spread over the run)", fontsize=8)
    cb.ax.tick_params(labelsize=7)
    fig.suptitle("Long runs: L in the principal axes on the sphere |L| = |L₀| with the polhodes of the "
                 "initial E and |L| (black: the run's own; dashed: the separatrix)", x=0.01, ha="left",
                 fontsize=9.5)
    save_png(fig, path)
    return True
