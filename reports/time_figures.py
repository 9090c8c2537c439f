"""The report's figures against time, at a scenario's default Δt (one column per engine family, one row
per component or quantity, each variant in its style: reports.canvas):

``trajectories``   the moving position / orientation components vs time, with the reference
``errors``         error vs time (log–log), every moving quantity
``conservation``   |relative drift| of energy / angular momentum / linear momentum vs time (log–log)

Each ``fig_*(res, sc, styles, path)`` draws its figure and returns whether it carried anything; what it
left out is said in ``canvas.NOTES[(sc, kind)]`` (docs/results.md, "The report").
"""
from __future__ import annotations

import numpy as np

from cross_checks.core.quantities import QUANTITIES, UNITS
from reference_sim.quaternion import sign_continuous
from reports import canvas
from reports.canvas import (
    LOG_FLOOR,
    NOTES,
    Curves,
    add_line,
    coinciding,
    diverged_at,
    family_grid,
    legend_entries,
    panel_title,
    positive,
    robust_limits,
    row_ylabel,
    same_limits,
    same_note,
)
from reports.data import LABELS
from reports.glance import families

__all__ = ["fig_trajectories", "fig_errors", "fig_conservation"]


def _time_panels(axes, res, sc, fams, styles, rows, log, ser=None):
    """Draw ``rows`` = [(label, fn(series) -> y or None)] × family columns; diverged runs truncated and
    marked; a row's panels get one y range (from the runs that did not diverge). Curves that coincide
    (:func:`coinciding`) are drawn so that both are seen; returns them ["a = b (row)"] for the caption."""
    ser = res.series(sc) if ser is None else ser
    same = []
    for i, (label, get) in enumerate(rows):
        keep, every = [], []
        for j, (fam, vs) in enumerate(fams.items()):
            ax = axes[i, j]
            curves = []   # (xy, style): the panel's variants, drawn as one artist (Curves)
            ref = ser.get("reference")
            if not log and ref is not None and get(ref) is not None:
                add_line(ax, ref["t_s"], get(ref), color="black", lw=3.2, alpha=0.28)
                keep.append(get(ref))
            for v in vs:
                if v not in ser or get(ser[v]) is None:
                    continue
                t, y = ser[v]["t_s"], np.asarray(get(ser[v]), dtype=float)
                tdiv = diverged_at(res, sc, v)
                ok = np.isfinite(y) & np.isfinite(t) & ((t > 0) if log else True)   # log t: no t = 0
                if tdiv is not None:
                    ok &= t <= tdiv
                y_draw = positive(y) if log else y
                st = styles[v]
                if ok.any():
                    curves.append((np.column_stack([t[ok], y_draw[ok]]), {**st, "name": v}))
                every.append(y_draw[ok])
                if tdiv is not None and ok.any():
                    k = np.flatnonzero(ok)[-1]
                    add_line(ax, [t[k]], [y_draw[k]], marker="x", ms=9, mew=2, color=st["color"], zorder=3)
                else:
                    keep.append(y[ok])
            if curves:
                span = np.ptp(np.concatenate([xy[:, 1] for xy, _ in curves])) if not log else None
                pairs = coinciding([(st["name"], xy[:, 0], xy[:, 1]) for xy, st in curves], log, span)
                halo = {b for _, b in pairs}
                same += [(a, b, label.split(" (")[0]) for a, b in pairs]
                wide = [(xy, st) for xy, st in curves if st["name"] in halo]
                if wide:    # under the others: a pale band around the curve it coincides with
                    ax.add_line(Curves([("line", xy[:, 0], xy[:, 1], (*st["color"][:3], 0.5), "-", 3.6)
                                         for xy, st in wide], capstyle="butt", zorder=1.9))
                ax.add_line(Curves([("line", xy[:, 0], xy[:, 1], (*st["color"][:3], 1.0), st["ls"], 1.1)
                                     for xy, st in curves], capstyle="butt"))
            if i == 0:
                panel_title(ax, fam)
            if ax.has_data():
                ax.autoscale_view()
        same_limits(axes[i], "y", robust_limits(keep, log) or robust_limits(every, log))
        row_ylabel(axes, i, label)
    same_limits(axes.flat, "x")
    for ax in axes[-1]:
        ax.set_xlabel("time t (s)", fontsize=8)
    return same


def _families_with_series(res, ser) -> dict:
    """``{family: [variants]}`` of the variants that have saved series, families without any left out."""
    fams = {f: [v for v in vs if v in ser] for f, vs in families(res.variants).items()}
    return {f: vs for f, vs in fams.items() if vs}


def _moving_components(ser):
    """[(label, field, index)] of the components that move along the reference (or, without one,
    along any series); the rest is named in the returned note."""
    comps = ([(f"{c} (m)", "x_W", i) for i, c in enumerate("xyz")]
             + [(f"q{c}", "q_WB", i) for i, c in enumerate("wxyz")])
    src = [ser["reference"]] if "reference" in ser else list(ser.values())
    moving, still = [], []
    for label, fld, i in comps:
        vals = (np.concatenate([np.asarray(s[fld][:, i], dtype=float) for s in src if fld in s])
                if src else np.zeros(1))
        vals = vals[np.isfinite(vals)]
        span = float(vals.max() - vals.min()) if vals.size else 0.0
        if span > 1e-9 * max(1.0, float(np.abs(vals).max()) if vals.size else 1.0):
            moving.append((label, fld, i))
        else:
            still.append(f"{label.split()[0]} = {float(vals[0]) if vals.size else 0.0:.3g}")
    return moving, still


def _continuous_series(ser) -> dict:
    """The series with every q_WB sign-continuous, each starting on the reference's sign."""
    ref = ser.get("reference", {}).get("q_WB")
    first = None if ref is None or not len(ref) else sign_continuous(ref)[0]
    return {who: ({**f, "q_WB": sign_continuous(f["q_WB"], first)} if "q_WB" in f else f)
            for who, f in ser.items()}


def fig_trajectories(res, sc, styles, path):
    info = res.scenario(sc)
    ser = res.series(sc)
    fams = _families_with_series(res, ser)
    ser = _continuous_series(ser)
    moving, still = _moving_components(ser)
    if not fams or not moving:
        NOTES[(sc, "trajectories")] = "nothing moves" if not moving else "no series"
        return False
    rows = [(label, (lambda s, fld=fld, i=i: s[fld][:, i] if fld in s else None)) for label, fld, i in moving]
    fig, axes = family_grid(len(rows), len(fams),
                      f"{sc}: trajectories at Δt = {info['dt_s']:g} s (thick grey: "
                      f"reference, {info['reference']})", panel_h=1.5,
                      legend=legend_entries(fams, styles, markers=False))
    same = _time_panels(axes, res, sc, fams, styles, rows, log=False, ser=ser)
    quat = (" Quaternions are drawn sign-continuous: q and −q are the same orientation, so each sample's "
            "sign is chosen to follow the previous one (a jump between them would be no motion)."
            if any(fld == "q_WB" for _, fld, _ in moving) else "")
    NOTES[(sc, "trajectories")] = ((("Not drawn, constant along the reference: " + ", ".join(still) + ".")
                                    if still else "") + quat + same_note(same)).strip()
    canvas.save_png(fig, path)
    return True


def fig_errors(res, sc, styles, path):
    info = res.scenario(sc)
    ser = res.series(sc)
    fams = _families_with_series(res, ser)
    moving = [q for q in QUANTITIES if info.get("varies", {}).get(q, True)]
    nonzero = [q for q in moving if any(np.any(np.asarray(ser[v].get(f"err_{q}", [0.0])) > 0)
                                        for vs in fams.values() for v in vs)]
    exact = [q for q in nonzero if _series_at_roundoff(res, sc, q, [v for vs in fams.values() for v in vs])]
    shown = [q for q in nonzero if q not in exact]
    exact_note = (" Not drawn, every variant's error at or below its run's round-off floor all along (exact "
                  "to within what can be measured): " + ", ".join(LABELS[q] for q in exact)
                  + ".") if exact else ""
    if not fams or not shown:
        NOTES[(sc, "errors")] = ("every error is zero" if not exact else exact_note.strip())
        return False
    rows = [(f"{LABELS[q]} error ({UNITS[q]})", (lambda s, q=q: s.get(f"err_{q}"))) for q in shown]
    fig, axes = family_grid(len(rows), len(fams),
                      f"{sc}: error against the reference vs time at Δt = {info['dt_s']:g} s "
                      f"(log scales; zero drawn at {LOG_FLOOR:g}; × marks a divergence)", log=True,
                      layout="time-log", legend=legend_entries(fams, styles, markers=False))
    same = _time_panels(axes, res, sc, fams, styles, rows, log=True)
    left = [LABELS[q] for q in QUANTITIES if q not in nonzero]
    NOTES[(sc, "errors")] = (("Not drawn: " + ", ".join(left)
                              + " (does not move, or zero error for every variant)."
                              if left else "") + exact_note + same_note(same)).strip()
    canvas.save_png(fig, path)
    return True


def _series_at_roundoff(res, sc, q, variants) -> bool:
    """Whether every variant's error in ``q`` stays at or below its run's round-off floor at the default
    Δt (the floor of its free-running convergence record, cross_checks.analysis.metrics.roundoff_floor)
    for the whole run: a panel of such errors shows only round-off."""
    dt = res.scenario(sc)["dt_s"]
    ser = res.series(sc)
    for v in variants:
        rec = next(iter(res.records(sc, v, q)), None)
        if rec is None or dt not in rec["dt_s"] or f"err_{q}" not in ser.get(v, {}):
            return False
        e = np.asarray(ser[v][f"err_{q}"], dtype=float)
        if not (np.all(np.isfinite(e)) and float(e.max(initial=0.0)) <= rec["floors"][rec["dt_s"].index(dt)]):
            return False
    return bool(variants)




_DRIFT_LABEL = {"energy": "energy drift |ΔE|/|E₀|", "angular_momentum": "ang. momentum drift |ΔL|/|L₀|",
                "linear_momentum": "lin. momentum drift |Δp|/|p₀|"}


def fig_conservation(res, sc, styles, path):
    """Drift of the quantities the physics conserves; False when none is conserved or none drifts."""
    info = res.scenario(sc)
    ser = res.series(sc)
    fams = _families_with_series(res, ser)
    kinds = [k for k in ("energy", "angular_momentum", "linear_momentum")
             if info["conserved"][k]["conserved"]]
    moving = [k for k in kinds if any(np.any(np.abs(np.asarray(ser[v].get(f"drift_{k}", [0.0]))) > 0)
                                      for vs in fams.values() for v in vs)]
    exact = [k.replace("_", " ") for k in kinds if k not in moving]
    NOTES[(sc, "conservation")] = ("Not drawn: " + ", ".join(exact)
                                   + " (conserved exactly by every variant).") if exact else ""
    if not fams or not moving:
        if not kinds:
            NOTES[(sc, "conservation")] = "the physics of this scenario conserves nothing"
        return False
    rows = [(_DRIFT_LABEL[k], (lambda s, k=k: None if f"drift_{k}" not in s else np.abs(s[f"drift_{k}"])))
            for k in moving]
    fig, axes = family_grid(len(rows), len(fams),
                      f"{sc}: relative drift of conserved quantities at Δt = {info['dt_s']:g} s "
                      f"(log scales; zero drawn at {LOG_FLOOR:g}; × marks a divergence)", log=True,
                      layout="time-log", legend=legend_entries(fams, styles, markers=False))
    same = _time_panels(axes, res, sc, fams, styles, rows, log=True)
    NOTES[(sc, "conservation")] = (NOTES[(sc, "conservation")] + same_note(same)).strip()
    canvas.save_png(fig, path)
    return True
