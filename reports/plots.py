"""PNG figures of one scenario, drawn from the saved results only (one idea per figure).

Figures (``plots/<scenario>__<kind>.png``):

``trajectories``   position and orientation components vs time, every variant and the reference
``errors``         error vs time (log scale), four quantities, every variant, at the default Δt
``conservation``   |relative drift| of energy / angular momentum / linear momentum vs time
``convergence``    final error vs Δt (log-log) with the fitted slopes and reference slope triangles
``local``          one-step (local) error vs Δt (log-log), same layout
``work``           work-precision: final error vs wall time (log-log)
"""
from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from cross_checks.core.quantities import COLUMN_STEM, QUANTITIES, UNITS  # noqa: E402
from reports.data import LABELS  # noqa: E402

__all__ = ["KINDS", "scenario_figures", "variant_styles"]

KINDS = ("trajectories", "errors", "conservation", "convergence", "local", "work")
DPI = 100
#: Errors of exactly zero cannot be drawn on a log axis; they are drawn at this value (and said so).
LOG_FLOOR = 1e-17

_ENGINE_STYLE = {"reference": "-", "mujoco": "--", "pybullet": ":"}
_MARKERS = {"reference": "o", "mujoco": "s", "pybullet": "^"}


def variant_styles(variants) -> dict:
    """A fixed colour / line style / marker per variant (same in every figure of a report)."""
    cmap = plt.get_cmap("tab20")
    # tab20 pairs a dark and a light shade; take the dark ones first so neighbours differ most.
    order = list(range(0, 20, 2)) + list(range(1, 20, 2))
    out = {}
    for i, v in enumerate(variants):
        eng = v.split(":", 1)[0]
        out[v] = {"color": cmap(order[i % 20]), "ls": _ENGINE_STYLE.get(eng, "-."),
                  "marker": _MARKERS.get(eng, "D")}
    return out


def _legend_handles(variants, styles, with_reference=False, markers=False):
    h = [Line2D([], [], color=styles[v]["color"], ls=styles[v]["ls"], marker=styles[v]["marker"] if markers else None,
                ms=4, lw=1.5, label=v) for v in variants]
    if with_reference:
        h.insert(0, Line2D([], [], color="black", lw=3, alpha=0.35, label="reference"))
    return h


def _figure(nrows, ncols, title, width=13.0, height=7.5):
    fig, axes = plt.subplots(nrows, ncols, figsize=(width, height), dpi=DPI, squeeze=False)
    fig.suptitle(title, fontsize=13, x=0.02, ha="left")
    return fig, axes


def _finish(fig, path, handles=None, legend_title=None):
    h_in = fig.get_size_inches()[1]
    top = 1.0 - 0.75 / h_in          # room for the title: 0.75 inch whatever the height
    bottom = 0.6 / h_in              # room for the x label
    right = 0.97
    if handles:
        leg = fig.legend(handles=handles, loc="center right", fontsize=8.5, frameon=False, title=legend_title,
                         title_fontsize=9)
        # leave exactly the legend's width (plus a margin) to the right of the axes
        width = leg.get_window_extent(fig.canvas.get_renderer()).width / fig.bbox.width
        right = min(0.97, 0.985 - width)
    fig.subplots_adjust(left=0.07, right=right, top=top, bottom=bottom, hspace=0.45, wspace=0.3)
    _save_png(fig, path)
    plt.close(fig)


def _save_png(fig, path):
    """Save as an 8-bit palette PNG: the figures use a few dozen colours, and a palette makes the
    files ~3× smaller than RGBA at no visible cost (no dithering). Deterministic for equal input."""
    import io

    from PIL import Image
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, metadata={"Software": None})
    buf.seek(0)
    with Image.open(buf) as im:
        q = im.convert("RGB").quantize(colors=256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
        q.save(path, format="PNG", compress_level=9)


def _positive(a):
    a = np.asarray(a, dtype=float)
    return np.where(a > 0, a, LOG_FLOOR)


# --- figures -------------------------------------------------------------------------------------------

def fig_trajectories(res, sc, styles, path):
    info = res.scenario(sc)
    ser = res.series(sc)
    variants = [v for v in res.variants if v in ser]
    fig, axes = _figure(4, 2, f"{sc}: trajectories at Δt = {info['dt_s']:g} s (reference: {info['reference']})",
                        height=9.0)
    comps = [("x_W", i, f"{c} (m)") for i, c in enumerate("xyz")]
    qcomps = [("q_WB", i, f"q{c}") for i, c in enumerate("wxyz")]
    slots = [axes[0, 0], axes[1, 0], axes[2, 0], axes[0, 1], axes[1, 1], axes[2, 1], axes[3, 1]]
    for ax, (fld, i, label) in zip(slots, comps + qcomps):
        ref = ser.get("reference")
        if ref is not None:
            ax.plot(ref["t_s"], ref[fld][:, i], color="black", lw=3.5, alpha=0.3)
        for v in variants:
            s = ser[v]
            ax.plot(s["t_s"], s[fld][:, i], color=styles[v]["color"], ls=styles[v]["ls"], lw=1.2)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        lo, hi = ax.get_ylim()
        if hi - lo < 1e-9 * max(1.0, abs(lo), abs(hi)):   # constant up to round-off: no 1e-18 axis
            mid = 0.5 * (lo + hi)
            ax.set_ylim(mid - 0.05 * max(1.0, abs(mid)), mid + 0.05 * max(1.0, abs(mid)))
            ax.ticklabel_format(axis="y", useOffset=False)
    axes[0, 0].set_title("COM position, world axes")
    axes[0, 1].set_title("orientation q_WB (w, x, y, z; sign matched to the reference)")
    axes[3, 0].axis("off")
    for ax in (axes[2, 0], axes[3, 1]):
        ax.set_xlabel("time t (s)")
    _finish(fig, path, _legend_handles(variants, styles, with_reference=True))


def fig_errors(res, sc, styles, path):
    info = res.scenario(sc)
    ser = res.series(sc)
    variants = [v for v in res.variants if v in ser]
    fig, axes = _figure(2, 2, f"{sc}: error against the reference vs time at Δt = {info['dt_s']:g} s "
                              f"(reference: {info['reference']}; zero drawn at {LOG_FLOOR:g})")
    for ax, q in zip(axes.flat, QUANTITIES):
        for v in variants:
            e = ser[v].get(f"err_{q}")
            if e is not None:
                ax.semilogy(ser[v]["t_s"], _positive(e), color=styles[v]["color"], ls=styles[v]["ls"], lw=1.2)
        ax.set_title(f"{LABELS[q]} error")
        ax.set_ylabel(f"{LABELS[q]} error ({UNITS[q]})")
        ax.set_xlabel("time t (s)")
        ax.grid(alpha=0.3, which="both")
    _finish(fig, path, _legend_handles(variants, styles))


_DRIFT_LABEL = {"energy": ("energy", "|E(t) − E(0)| / |E(0)|"),
                "angular_momentum": ("world angular momentum about the COM", "|L(t) − L(0)| / |L(0)|"),
                "linear_momentum": ("linear momentum", "|p(t) − p(0)| / |p(0)|")}


def fig_conservation(res, sc, styles, path):
    """Returns False (and draws nothing) when the physics of the scenario conserves nothing."""
    info = res.scenario(sc)
    ser = res.series(sc)
    variants = [v for v in res.variants if v in ser]
    kinds = [k for k in ("energy", "angular_momentum", "linear_momentum") if info["conserved"][k]["conserved"]]
    if not kinds or not variants:
        return False
    fig, axes = _figure(1, len(kinds), f"{sc}: drift of conserved quantities at Δt = {info['dt_s']:g} s "
                                       f"(zero drawn at {LOG_FLOOR:g})", width=13.0, height=5.0)
    for ax, k in zip(axes[0], kinds):
        for v in variants:
            d = ser[v].get(f"drift_{k}")
            if d is not None:
                ax.semilogy(ser[v]["t_s"], _positive(np.abs(d)), color=styles[v]["color"], ls=styles[v]["ls"], lw=1.2)
        title, ylab = _DRIFT_LABEL[k]
        ax.set_title(title)
        ax.set_ylabel(f"{ylab} (relative)")
        ax.set_xlabel("time t (s)")
        ax.grid(alpha=0.3, which="both")
    _finish(fig, path, _legend_handles(variants, styles))
    return True


def _slope_triangles(ax, dts, orders=(1, 2, 4)):
    """Reference slope triangles in the lower right of a log-log axis."""
    lo, hi = ax.get_ylim()
    x1 = max(dts)
    x0 = x1 / 2.0
    span = math.log10(hi) - math.log10(lo)
    for k, p in enumerate(orders):
        y0 = 10 ** (math.log10(lo) + span * (0.06 + 0.16 * k))
        y1 = y0 * (x1 / x0) ** p
        ax.plot([x0, x1, x1, x0], [y0, y0, y1, y0], color="0.35", lw=0.9)
        ax.text(x1 * 1.05, math.sqrt(y0 * y1), f"{p}", fontsize=8, color="0.25", va="center")


def _log_x_ticks(ax):
    """Major decade labels only: the minor '2×10⁻³ 3×10⁻³ …' labels of a short log axis overlap."""
    from matplotlib.ticker import NullFormatter
    ax.xaxis.set_minor_formatter(NullFormatter())


def _ladder_panel(ax, res, sc, q, styles, mode):
    stem = COLUMN_STEM[q]
    col = f"{stem}_err_final" if mode == "free_running" else f"{stem}_local_err"
    recs = {r["engine"]: r for r in res.records(sc, quantity=q, mode=mode)}
    all_dt = []
    drawn = False
    for v in res.variants:
        rows = sorted([r for r in res.rows_for(sc, v) if r["in_ladder"]], key=lambda r: -r["dt"])
        if not rows:
            continue
        dt = np.array([r["dt"] for r in rows])
        e = np.array([r[col] for r in rows], dtype=float)
        ok = np.isfinite(e)
        if not ok.any():
            continue
        all_dt += dt.tolist()
        st = styles[v]
        ax.loglog(dt[ok], _positive(e[ok]), color=st["color"], ls=st["ls"], lw=1.0, marker=st["marker"], ms=4,
                  mfc="white")
        rec = recs.get(v)
        if rec is not None and rec["order"] is not None:
            fitted = np.array(rec["fitted"], dtype=bool)
            fdt = np.array(rec["dt_s"])[fitted]
            fe = np.array(rec["errors"], dtype=float)[fitted]
            ax.loglog(fdt, fe, ls="none", marker=st["marker"], ms=4, color=st["color"])
        drawn = True
    if recs:
        floors = next(iter(recs.values()))["floors"]
        fdt = next(iter(recs.values()))["dt_s"]
        ax.loglog(fdt, floors, color="0.5", lw=4, alpha=0.25, solid_capstyle="butt")
    if drawn:
        _slope_triangles(ax, all_dt)
    ax.set_title(f"{LABELS[q]}")
    if all_dt:
        from matplotlib.ticker import FixedLocator, NullLocator
        ticks = sorted(set(all_dt))
        ax.xaxis.set_major_locator(FixedLocator(ticks))
        ax.xaxis.set_minor_locator(NullLocator())
        ax.set_xticklabels([f"{d:g}" for d in ticks], fontsize=8)
    ax.set_xlabel("time step Δt (s)")
    what = "final" if mode == "free_running" else "one-step (local)"
    ax.set_ylabel(f"{what} {LABELS[q]} error ({UNITS[q]})")
    ax.grid(alpha=0.3, which="both")


def _order_table(res, sc, mode):
    """Legend lines "variant  p_x / p_θ / p_v / p_ω" (— where no order was fitted)."""
    lines = []
    for v in res.variants:
        recs = {r["quantity"]: r for r in res.records(sc, v, mode=mode)}
        if not recs:
            continue
        def one(q):
            r = recs.get(q)
            if r is None:
                return "—"
            if r["verdict"] == "at_roundoff":
                return "exact"
            if r["order"] is None:
                return {"diverged": "diverged", "failed": "failed"}.get(r["verdict"], "n/a")
            o = 0.0 if abs(r["order"]) < 0.005 else r["order"]
            if r["verdict"] == "pre_asymptotic":
                return f"({o:.2f})"
            return f"{o:.2f}" if r["verdict"] == "converges" else "no"
        lines.append((v, " / ".join(one(q) for q in QUANTITIES)))
    return lines


def fig_ladder(res, sc, styles, path, mode):
    what = "final error vs Δt" if mode == "free_running" else "one-step (local) error vs Δt"
    fig, axes = _figure(2, 2, f"{sc}: {what}; filled markers: points used for the fitted order; grey band: "
                              "round-off floor; triangles: slopes 1, 2, 4", height=8.5)
    for ax, q in zip(axes.flat, QUANTITIES):
        _ladder_panel(ax, res, sc, q, styles, mode)
    table = dict(_order_table(res, sc, mode))
    variants = [v for v in res.variants if v in table]
    handles = [Line2D([], [], color=styles[v]["color"], ls=styles[v]["ls"], marker=styles[v]["marker"], ms=4,
                      mfc="white", label=f"{v}\n   {table[v]}") for v in variants]
    _finish(fig, path, handles, legend_title="fitted order (position /\norientation / velocity /\nangular velocity); no: does\nnot converge; exact: round-off;\n(…): pre-asymptotic, not judged")
    return True


def fig_work(res, sc, styles, path):
    qs = ("position", "orientation")
    fig, axes = _figure(1, 2, f"{sc}: work-precision — final error vs wall time of the run "
                              f"(every Δt of the ladder; zero drawn at {LOG_FLOOR:g})", height=5.5)
    variants = []
    for ax, q in zip(axes[0], qs):
        col = f"{COLUMN_STEM[q]}_err_final"
        for v in res.variants:
            rows = sorted([r for r in res.rows_for(sc, v) if r["in_ladder"] and r["status"] == "ok"],
                          key=lambda r: -r["dt"])
            w = np.array([r["wall_s"] for r in rows], dtype=float)
            e = np.array([r[col] for r in rows], dtype=float)
            ok = np.isfinite(w) & np.isfinite(e) & (w > 0)
            if not ok.any():
                continue
            if v not in variants:
                variants.append(v)
            st = styles[v]
            ax.loglog(w[ok], _positive(e[ok]), color=st["color"], ls=st["ls"], marker=st["marker"], ms=4, lw=1.0)
        ax.set_title(f"{LABELS[q]}")
        _log_x_ticks(ax)
        ax.set_xlabel("wall time of the run (s)")
        ax.set_ylabel(f"final {LABELS[q]} error ({UNITS[q]})")
        ax.grid(alpha=0.3, which="both")
    _finish(fig, path, _legend_handles(variants, styles, markers=True))
    return True


def scenario_figures(res, sc, plot_dir) -> list:
    """Draw every figure of scenario ``sc`` into ``plot_dir``; returns ``[(kind, filename)]`` drawn."""
    from cross_checks.sweep.results_dir import inside, safe_file_stem
    styles = variant_styles(res.variants)
    out = []
    for kind in KINDS:
        name = f"{safe_file_stem(sc)}__{kind}.png"
        path = inside(plot_dir, name)
        if kind == "trajectories":
            ok = bool(res.series(sc).get("reference")) or any(v in res.series(sc) for v in res.variants)
            if ok:
                fig_trajectories(res, sc, styles, path)
        elif kind == "errors":
            ok = any(v in res.series(sc) for v in res.variants)
            if ok:
                fig_errors(res, sc, styles, path)
        elif kind == "conservation":
            ok = fig_conservation(res, sc, styles, path)
        elif kind == "convergence":
            ok = fig_ladder(res, sc, styles, path, "free_running")
        elif kind == "local":
            ok = fig_ladder(res, sc, styles, path, "one_step")
        else:
            ok = fig_work(res, sc, styles, path)
        if ok:
            out.append((kind, name))
    return out
