"""``rbcheck check --plot FILE.png``: the figure of one check (or of a ladder), drawn from the check's
result only (no simulation here).

One file: the user's trajectory, the reference and the closest correct scheme (position, orientation
and angular velocity components), then the local evidence — each quantity's one-step defect (or
acceleration residual) divided by its allowance — and the free-running error divided by its allowance,
over time on a log scale; 1 is the allowance. A ladder: final error against Δt per quantity.
"""
from __future__ import annotations

import textwrap

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.ticker import NullFormatter

from reports.canvas import DPI, LOG_FLOOR, new_figure, save_png

__all__ = ["check_figure", "ladder_figure"]

QCOLORS = {"position": "tab:blue", "velocity": "tab:green", "orientation": "tab:red",
           "angular_velocity": "tab:purple", "conserved energy": "tab:orange",
           "conserved angular_momentum": "tab:brown", "conserved quaternion_norm": "tab:gray"}
COMP_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red")


def _hemisphere(q, q_ref):
    s = np.sign(np.sum(q * q_ref, axis=-1, keepdims=True))
    s[s == 0] = 1.0
    return q * s


def _components(ax, t, user, ref, closest, labels, title, unit):
    for i, lab in enumerate(labels):
        c = COMP_COLORS[i]
        ax.plot(t, ref[:, i], color=c, lw=4, alpha=0.25)
        if closest is not None:
            ax.plot(closest[0], closest[1][:, i], color=c, lw=1.2, ls="--")
        ax.plot(t, user[:, i], color=c, lw=1.2, label=lab)
    ax.set_title(title, fontsize=10)
    ax.set_ylabel(unit)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncol=len(labels), loc="best")


def _ratio_axis(ax, series, title):
    """``series``: name -> (t, ratio, decisive mask or None); the non-decisive part is drawn faded."""
    ax.set_yscale("log")
    for q, (t, r, decisive) in series.items():
        t = np.asarray(t, dtype=float)
        r = np.asarray(r, dtype=float)
        dec = np.ones(len(t), dtype=bool) if decisive is None else np.asarray(decisive, dtype=bool)
        c = QCOLORS.get(q, "black")
        shown = np.where(r > 0, r, LOG_FLOOR)
        lw = 0.6 if q.endswith("quaternion_norm") else 0.9
        ax.plot(t, np.where(dec, shown, np.nan), color=c, lw=lw, label=q.replace("_", " "))
        if not dec.all():
            ax.plot(t, np.where(dec, np.nan, shown), color=c, lw=0.8, alpha=0.35, ls="--")
        over = np.flatnonzero(dec & ~(r <= 1.0))
        if over.size:
            k = over[0]
            ax.plot(t[k], shown[k] if np.isfinite(shown[k]) else 1.0, marker="v", color=c, ms=9, mec="black")
    ax.axhline(1.0, color="black", lw=1.5, ls=":")
    ax.text(0.005, 1.0, " allowance", transform=ax.get_yaxis_transform(), va="bottom", fontsize=8)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("time t (s)")
    ax.set_ylabel("value / allowance")
    ax.grid(alpha=0.3, which="both")
    lo, hi = ax.get_ylim()
    ax.set_ylim(max(lo, 1e-8), max(hi, 10.0))
    ax.legend(fontsize=7.5, loc="lower right", ncol=2, framealpha=0.85)


def _free_errors(ax, res):
    """Free-running error against the reference over time (log), for files without velocities."""
    ax.set_yscale("log")
    for e in res.evidence:
        if e.kind == "free-running" and e.series:
            v = np.asarray(e.series["value"], dtype=float)
            ax.plot(e.series["t_s"], np.where(v > 0, v, LOG_FLOOR), color=QCOLORS.get(e.quantity, "black"),
                    lw=1.1, label=f"{e.quantity.replace('_', ' ')} ({e.unit})")
    ax.set_title("free-running error vs the reference (no velocity columns)", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="lower right")


def _polhode_paths(res, scenario):
    """``(moments, torque free, [(gid, L in principal axes (n, 3) N m s, style)])`` of the file, the reference
    and the closest correct scheme, or None when the file has no orientation or angular velocity or the
    reference does not rotate (reports.polhode)."""
    from reports.polhode import momentum_principal, principal_frame, rotating
    s = res.series
    if not {"orientation", "angular_velocity"} <= set(s["present"]):
        return None
    inertia = scenario.problem.body.inertia_B
    y, y_ref = np.asarray(s["y"], dtype=float), np.asarray(s["y_ref"], dtype=float)
    L_ref = momentum_principal(y_ref[:, 6:10], y_ref[:, 10:13], inertia)
    if not rotating(L_ref):
        return None
    with np.errstate(all="ignore"):
        L = momentum_principal(y[:, 6:10], y[:, 10:13], inertia)
    paths = [("reference", L_ref, {"color": "#000000", "lw": 4.0, "alpha": 0.25, "ends": False}),
             ("file", L, {"color": "tab:red", "lw": 1.3})]
    closest = s.get("closest")
    if closest:
        paths.append((closest[0], momentum_principal(closest[2][:, 6:10], closest[2][:, 10:13], inertia),
                      {"color": "tab:blue", "lw": 1.1, "ls": "--"}))
    forces = scenario.problem.forces
    torque_free = bool(forces.torque_free and forces.angular_velocity_decay == 1.0)
    return principal_frame(inertia)[0], torque_free, paths


def _polhode_axis(ax, polhode, res) -> None:
    from reports.polhode import polhode_panel
    moments, torque_free, paths = polhode
    polhode_panel(ax, moments, paths, torque_free, key=("check", res.source))
    ax.set_title("polhode: L in the principal axes" + (", |L| = |L₀|" if torque_free else " (direction)"),
                 fontsize=10)
    lines = ["red: the file, thick grey: the reference"
             + (",\ndashed blue: the closest correct scheme" if len(paths) > 2 else ""),
             "grey curves: polhodes of the reference's E and |L|\n(black: its own, dashed: the separatrix)"
             if torque_free else "torques act: E and |L| change, no polhodes",
             "front of the sphere solid, back faint; ○ start, □ end"]
    ax.text(0.5, -0.02, "\n".join(lines), transform=ax.transAxes, fontsize=8, va="top", ha="center")


def check_figure(res, scenario, path) -> None:
    """Draw the figure of one CheckResult to ``path`` (PNG)."""
    s = res.series
    polhode = _polhode_paths(res, scenario)
    fig = new_figure((18.0 if polhode else 14.0, 8.8), dpi=DPI)
    gs = fig.add_gridspec(2, 4 if polhode else 3, height_ratios=[1.0, 1.0], hspace=0.45, wspace=0.28,
                          left=0.05 if polhode else 0.06, right=0.985, top=0.83, bottom=0.07)
    head = (("PASS: " + res.verdict) if res.passed
            else ("FAIL: " + res.reasons[0] if res.reasons else res.verdict))
    head = head.split(" (`--scheme")[0]   # the option is said in the terminal; the figure keeps the cause
    lines = textwrap.wrap(f"{res.source} on {res.scenario} — {head}", 140)[:2]
    if res.likely_causes:
        lines += textwrap.wrap("likely cause: " + res.likely_causes[0].split(" — ")[0], 140)[:1]
    fig.suptitle("\n".join(lines), x=0.01, y=0.985, ha="left", va="top", fontsize=10.5,
                 color="darkgreen" if res.passed else "darkred")
    t, y, y_ref = s["t_s"], s["y"], s["y_ref"]
    closest = s.get("closest")
    present = s["present"]
    label_closest = closest[0] if closest else None
    c_pos = (closest[1], closest[2][:, 0:3]) if closest else None
    ax = fig.add_subplot(gs[0, 0])
    if "position" in present:
        _components(ax, t, y[:, 0:3], y_ref[:, 0:3], c_pos, ("x", "y", "z"), "COM position, world", "m")
    else:
        ax.text(0.5, 0.5, "no position columns", ha="center", transform=ax.transAxes)
    ax = fig.add_subplot(gs[0, 1])
    if "orientation" in present:
        q = _hemisphere(y[:, 6:10], y_ref[:, 6:10])
        c_q = None
        if closest:
            ref_at = y_ref[np.searchsorted(t, closest[1]).clip(0, len(t) - 1), 6:10]
            c_q = (closest[1], _hemisphere(closest[2][:, 6:10], ref_at))
        _components(ax, t, q, y_ref[:, 6:10], c_q, ("qw", "qx", "qy", "qz"),
                    "orientation q_WB (sign as the reference)", "")
    else:
        ax.text(0.5, 0.5, "no orientation columns", ha="center", transform=ax.transAxes)
    ax = fig.add_subplot(gs[0, 2])
    if "angular_velocity" in present:
        c_w = (closest[1], closest[2][:, 10:13]) if closest else None
        _components(ax, t, y[:, 10:13], y_ref[:, 10:13], c_w,
                    ("ωx", "ωy", "ωz"), "angular velocity, world", "rad/s")
    elif "velocity" in present:
        c_v = (closest[1], closest[2][:, 3:6]) if closest else None
        _components(ax, t, y[:, 3:6], y_ref[:, 3:6], c_v, ("vx", "vy", "vz"), "COM velocity, world", "m/s")
    else:
        _free_errors(ax, res)
    for a in fig.axes:
        a.set_xlabel("time t (s)")
    local = {q: (s["ratios_t_s"], r, None) for q, r in s["ratios"].items()}
    kind = "one-step defect" if len(present) == 4 else "acceleration residual (from the poses)"
    _ratio_axis(fig.add_subplot(gs[1, :2]), local, f"{kind} / its allowance  (▼ first time over)")
    free = {}
    for e in res.evidence:
        if e.kind in ("free-running", "conserved") and e.series:
            t_e = e.series["t_s"]
            dec = None if e.decisive_until_s is None else t_e <= e.decisive_until_s
            r = e.series["value"] / np.where(e.series["allowance"] > 0, e.series["allowance"], np.inf)
            if e.kind == "conserved":   # drifts drawn as their running maximum (round-off flickers otherwise)
                r = np.fmax.accumulate(r)
            free[("conserved " if e.kind == "conserved" else "") + e.quantity] = (t_e, r, dec)
    if polhode:
        _polhode_axis(fig.add_subplot(gs[0, 3]), polhode, res)
    _ratio_axis(fig.add_subplot(gs[1, 2:]), free,
                "free-running error, conserved drift / allowance\n"
                "(drifts: running max; dashed: past the cap)")
    handles = [Line2D([], [], color="gray", lw=1.2, label=f"{res.source} (the file)"),
               Line2D([], [], color="gray", lw=4, alpha=0.3, label=f"reference ({res.reference_label})")]
    if label_closest:
        handles.append(Line2D([], [], color="gray", lw=1.2, ls="--",
                              label=f"{label_closest} run free (closest correct)"))
    fig.legend(handles=handles, loc="upper right",
               bbox_to_anchor=(0.74 if polhode else 0.985, 0.895), ncol=3, fontsize=9, frameon=False)
    save_png(fig, path)


def ladder_figure(results, ladder, scenario, path) -> None:
    """Final error against Δt (log-log) per quantity, with the fitted order."""
    recs = ladder["convergence"]
    fig = new_figure((4.0 * max(1, len(recs)), 4.6), dpi=DPI)
    axes = fig.subplots(1, max(1, len(recs)), squeeze=False)
    fig.suptitle(("PASS: " if ladder["passed"] else "FAIL: ")
                 + "\n".join(textwrap.wrap(ladder["verdict"], 140)[:2]), x=0.01, ha="left", fontsize=10,
                 color="darkgreen" if ladder["passed"] else "darkred")
    for ax, r in zip(axes[0], recs):
        dt = np.asarray(r["dt_s"], dtype=float)
        e = np.asarray(r["errors"], dtype=float)
        fitted = np.asarray(r.get("fitted", [True] * len(dt)), dtype=bool)
        c = QCOLORS[r["quantity"]]
        ax.loglog(dt, np.where(e > 0, e, LOG_FLOOR), "-", color=c, lw=1.2)
        ax.loglog(dt[fitted], np.where(e > 0, e, LOG_FLOOR)[fitted], "o", color=c, label="fitted")
        ax.loglog(dt[~fitted], np.where(e > 0, e, LOG_FLOOR)[~fitted],
                  "o", mfc="white", color=c, label="not fitted")
        if r.get("floors"):
            ax.loglog(dt, np.asarray(r["floors"], dtype=float), ":", color="gray", label="round-off floor")
        ax.set_xticks(dt)
        ax.set_xticklabels([f"{d:g}" for d in dt], rotation=30, fontsize=8)
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.legend(fontsize=7, loc="best")
        order = "–" if r["order"] is None else f"{r['order']:.2f}"
        ax.set_title(f"{r['quantity'].replace('_', ' ')}: order {order}\n{r['assessment']}", fontsize=9)
        ax.set_xlabel("Δt (s)")
        ax.set_ylabel("final error")
        ax.grid(alpha=0.3, which="both")
    fig.subplots_adjust(left=0.07, right=0.98, top=0.72, bottom=0.14, wspace=0.35)
    save_png(fig, path)
