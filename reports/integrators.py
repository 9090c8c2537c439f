"""The "integrators" page (``integrators.html``): every engine variant — the reference's schemes and every
engine's — ranked on work-precision (the ranking module's error at a common cost and cost at a common
accuracy, from the sweep's Δt ladders: reports.ranking) and on long-run conservation (the long runs of
summary.json ``long_runs``: cross_checks.analysis.long_run), each finding in one sentence.

Read from the results directory only (summary.json, results.csv, series/<long run>.npz); three figures,
drawn by :func:`draw_figures`: the work-precision ranking, the long-run conservation ranking (horizontal
bars, one row per variant: readable with any number of variants), and the separatrix distance δ(t) of the
variants whose δ drifted.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["IntegratorsView", "integrators_view", "draw_figures", "PAGE", "FIGURES", "conservation_score",
           "long_cell_class"]

PAGE = "integrators.html"
#: The page's figures (plots/<name>): what each shows.
FIGURES = {"integrators-work-precision.png": "work precision", "integrators-long-runs.png": "long runs",
           "integrators-separatrix.png": "separatrix", "integrators-polhode.png": "polhode"}
#: The long-run verdicts in words, and the colour of their bars (Okabe–Ito: told apart by colour-blind
#: readers; the hatch marks a divergence in greyscale too).
VERDICT_WORDS = {"crosses_separatrix": "crosses the separatrix", "toward_intermediate": "drifts toward the "
                 "intermediate axis", "away_from_intermediate": "drifts away from the intermediate axis",
                 "none": "no secular drift of δ", "diverged": "diverged", "failed": "failed"}
VERDICT_COLOURS = {"crosses_separatrix": "#CC79A7", "toward_intermediate": "#D55E00",
                   "away_from_intermediate": "#0072B2", "none": "#999999", "diverged": "#000000",
                   "failed": "#E69F00"}
#: The page's figures' resolution (dots per inch): full-colour PNGs, 1300 px wide.
_DPI = 100
#: A drift below this is drawn at it (round-off is at ~1e-16 relative; a log axis needs a floor).
_DRAW_FLOOR = 1e-17


def conservation_score(rec) -> float:
    """The largest drift of a long run: the relative energy and |L| drifts and L's turn (rad), whichever is
    largest (inf for a run that diverged or failed): what the conservation ranking orders by."""
    if rec.get("status") != "ok":
        return math.inf
    vals = [rec.get(k) for k in ("energy_drift_max", "momentum_drift_max", "direction_drift_max_rad")]
    vals = [float(v) for v in vals if isinstance(v, (int, float)) and math.isfinite(v)]
    return max(vals) if vals else math.inf


def long_cell_class(rec) -> str:
    """The colour of one long run's cell (display only): ``bad`` it contradicts what its variant declares,
    ``diverged`` / ``bad`` it diverged / failed, ``acc1`` (green) it keeps what it declares and conserves
    (its largest drift below tol.REPORT_LONG_RUN_CONSERVES), ``noconv`` (amber) it drifts more — as declared
    or with nothing declared —, "" no claim and no drift to speak of."""
    from cross_checks.core.tolerances import REPORT_LONG_RUN_CONSERVES
    if rec.get("matches_expectation") is False or rec.get("status") == "failed":
        return "bad"
    if rec.get("status") == "diverged":
        return "diverged"
    conserves = conservation_score(rec) <= REPORT_LONG_RUN_CONSERVES
    if rec.get("matches_expectation") is True:
        return "acc1" if conserves else "noconv"
    return "" if conserves else "noconv"


@dataclass
class LongStanding:
    """A variant on the long runs: ``score`` (the largest over the long runs of conservation_score: the
    worst run, so a run that lost 63 % of its energy reads 0.63; inf when one diverged), ``worst`` (that
    run's name), ``rank`` (1 = keeps best; runs that diverged last, the later divergence first),
    ``records`` {long run: the summary's record}, ``contradicts`` (the long runs where the judge says it does
    not keep what it declares)."""

    variant: str
    score: float | None
    records: dict = field(default_factory=dict)
    worst: str = ""
    rank: int | None = None
    contradicts: list = field(default_factory=list)
    diverged: list = field(default_factory=list)


@dataclass
class IntegratorsView:
    """What the page shows: the variants (all of the sweep's), the work-precision standings (reports.ranking
    overall), the long runs' names and standings, and one sentence per variant."""

    variants: list
    work: list
    long_runs: list
    long: list
    sentences: dict
    findings: list


def long_standings(res) -> list:
    """Every variant with a long run, ranked by conservation (LongStanding)."""
    recs = res.summary.get("long_runs") or []
    names = [s["name"] for s in res.summary.get("long_run_scenarios") or []]
    out = []
    for v in res.variants:
        mine = {r["scenario"]: r for r in recs if r["engine"] == v}
        if not mine:
            continue
        scores = {n: conservation_score(mine[n]) for n in names if n in mine}
        worst = max(scores, key=scores.get) if scores else ""
        st = LongStanding(v, scores[worst] if scores else None, mine, worst)
        st.contradicts = [n for n in names if n in mine and mine[n].get("matches_expectation") is False]
        st.diverged = [(n, mine[n].get("diverged_at_s")) for n in names
                       if n in mine and mine[n].get("status") != "ok"]
        out.append(st)

    def key(s):
        first_div = min((t for _, t in s.diverged if isinstance(t, (int, float))), default=0.0)
        return (len(s.diverged), -first_div, s.score if s.score is not None else math.inf, s.variant)

    out.sort(key=key)
    for i, s in enumerate(out, start=1):
        s.rank = i
    return out


def _fmt(x, unit="") -> str:
    if x is None or not isinstance(x, (int, float)) or not math.isfinite(x):
        return "–"
    return f"{x:.2g}{(' ' + unit) if unit else ''}"


def _long_sentence(st: LongStanding, n_ranked: int) -> str:
    from reports.ranking import ordinal
    parts = [f"{ordinal(st.rank)} of {n_ranked} in long-run conservation"]
    if st.diverged:
        parts[0] += " (diverged on " + ", ".join(f"{n} at t = {_fmt(t, 's')}" for n, t in st.diverged) + ")"
    else:
        parts[0] += f" (largest drift {_fmt(st.score)}, on {st.worst})"
    claims = [r for r in st.records.values() if r.get("matches_expectation") is not None]
    if st.contradicts:
        parts.append("CONTRADICTS what it declares on " + ", ".join(st.contradicts))
    elif claims:
        parts.append("keeps what it declares (" + (", ".join(claims[0].get("expected_keeps") or [])
                                                   .replace("_", " ") or "its separatrix distance") + ")")
    else:
        parts.append("declares no invariant (its drifts are measured, not judged)")
    kinds = {}
    for n, r in st.records.items():
        if r.get("verdict") in ("toward_intermediate", "crosses_separatrix", "away_from_intermediate"):
            kinds.setdefault(VERDICT_WORDS[r["verdict"]], []).append(n)
    parts += [f"{k} on {', '.join(ns)}" for k, ns in kinds.items()]
    return "; ".join(parts)


def integrators_view(res, rk=None) -> IntegratorsView:
    """The page's content from a loaded results directory (``rk``: reports.ranking.ranking(res), computed
    here when not given)."""
    from reports.ranking import engine_sentence, ranking
    rk = rk if rk is not None else ranking(res)
    overall = {s.variant: s for s in rk.groups.get("overall", {"standings": []})["standings"]}
    work = sorted(overall.values(), key=lambda s: (s.acc_rank or 10 ** 6, s.cost_rank or 10 ** 6, s.variant))
    long = long_standings(res)
    by_v = {s.variant: s for s in long}
    sentences = {}
    for v in res.variants:
        words = []
        if v in overall:
            words.append(engine_sentence(rk, v).split(": ", 1)[1].rstrip("."))
        else:
            words.append("no work-precision curve (it ran no Δt ladder in this sweep)")
        if v in by_v:
            words.append(_long_sentence(by_v[v], len(long)))
        sentences[v] = f"{v}: " + "; ".join(words) + "."
    findings = [r for r in res.summary.get("long_runs") or [] if r.get("finding") or
                r.get("matches_expectation") is False or r.get("status") != "ok"]
    names = [s["name"] for s in res.summary.get("long_run_scenarios") or []]
    return IntegratorsView(res.variants, work, names, long, sentences, findings)


# --- figures -------------------------------------------------------------------------------------------

def draw_figures(res, view: IntegratorsView, out_dir) -> list:
    """Draw the page's figures into ``out_dir``; returns the file names drawn (none without data)."""
    from pathlib import Path
    out = []
    if view.work:
        _work_figure(view, Path(out_dir) / "integrators-work-precision.png")
        out.append("integrators-work-precision.png")
    if view.long:
        _long_figure(view, Path(out_dir) / "integrators-long-runs.png")
        out.append("integrators-long-runs.png")
        if _separatrix_figure(res, view, Path(out_dir) / "integrators-separatrix.png"):
            out.append("integrators-separatrix.png")
        from reports.polhode import fig_long_polhode  # the polhodes of the long runs (reports.polhode)
        if fig_long_polhode(res, view, Path(out_dir) / "integrators-polhode.png"):
            out.append("integrators-polhode.png")
    return out


def _bar_figure(n_rows, n_cols, width_in=13.0):
    """A figure of ``n_cols`` panels side by side sharing their y axis (one bar row per variant), on the
    report's canvas."""
    from reports.canvas import new_figure
    height = 1.4 + 0.26 * max(n_rows, 4)
    fig = new_figure((width_in, height), dpi=_DPI)
    return fig, fig.subplots(1, n_cols, sharey=True, squeeze=False)[0]


def _work_figure(view, path) -> None:
    from reports.canvas import save_png
    work = view.work
    fig, axes = _bar_figure(len(work), 3)
    y = list(range(len(work)))
    labels = [s.variant + ("  ✗" if s.contradicts_on else "") for s in work]
    cols = (("acc_score", "error at a common cost\n(× the best; ranked by this)", "#0072B2"),
            ("cost_score", "cost at a common accuracy\n(× the cheapest)", "#009E73"),
            ("per_step_us", "cost per step (µs, median\nover the ladders' runs)", "#E69F00"))
    for ax, (attr, title, colour) in zip(axes, cols):
        vals = [getattr(s, attr) for s in work]
        got = [v for v in vals if v is not None and math.isfinite(v) and v > 0]
        lo = min(got) / 2 if got else 0.5
        for yi, v in zip(y, vals):
            if v is None or not math.isfinite(v) or v <= 0:
                ax.text(lo * 1.1, yi, "not ranked", va="center", fontsize=8, color="#555555")
                continue
            ax.barh(yi, v - lo, left=lo, color=colour, height=0.7)
            ax.text(v * 1.08, yi, _fmt(v), va="center", fontsize=8)
        ax.set_xscale("log")
        ax.set_title(title, fontsize=10)
        ax.grid(axis="x", which="major", color="#dddddd")
        ax.set_axisbelow(True)
        if got:
            ax.set_xlim(lo, max(got) * 6)
    axes[0].set_yticks(y, labels, fontsize=9)
    axes[0].invert_yaxis()
    fig.suptitle("Work precision over every scenario's Δt ladder (reports.ranking): top = most accurate at a "
                 "common cost; ✗ = a verdict contradicts its expectations", fontsize=10)
    fig.tight_layout()
    save_png(fig, path, palette=False, dpi=_DPI)


def _long_figure(view, path) -> None:
    from matplotlib.patches import Patch

    from reports.canvas import save_png
    long, names = view.long, view.long_runs
    fig, axes = _bar_figure(len(long), len(names))
    y = list(range(len(long)))
    finite = [conservation_score(r) for s in long for r in s.records.values()]
    finite = [max(v, _DRAW_FLOOR) for v in finite if math.isfinite(v)]
    lo, hi = (min(finite) / 3, max(finite) * 3e3) if finite else (1e-17, 10.0)
    for ax, name in zip(axes, names):
        for yi, s in zip(y, long):
            r = s.records.get(name)
            if r is None:
                continue
            v = conservation_score(r)
            verdict = r.get("verdict") or "failed"
            colour = VERDICT_COLOURS.get(verdict, "#999999")
            if math.isinf(v):
                ax.barh(yi, hi - lo, left=lo, color="white", edgecolor="#000000", hatch="///", height=0.7)
                at = r.get("diverged_at_s")
                ax.text(lo * 1.5, yi, f"diverged at {_fmt(at, 's')}" if verdict == "diverged" else "failed",
                        va="center", fontsize=8, backgroundcolor="white")
                continue
            end = max(v, lo * 1.05)
            ax.barh(yi, end - lo, left=lo, color=colour, height=0.7)
            mark = "  ✗" if r.get("matches_expectation") is False else ""
            ax.text(end * 1.4, yi, f"{_fmt(v)}{mark}", va="center", fontsize=8,
                    color="#B00000" if mark else "#222222")
        ax.set_xscale("log")
        ax.set_xlim(lo, hi)
        ax.set_title(f"{name}\nlargest drift: E, |L| (relative), L's turn (rad)", fontsize=10)
        ax.grid(axis="x", which="major", color="#dddddd")
        ax.set_axisbelow(True)
    axes[0].set_yticks(y, [s.variant for s in long], fontsize=9)
    axes[0].invert_yaxis()
    handles = [Patch(facecolor=c, label=VERDICT_WORDS[k]) for k, c in VERDICT_COLOURS.items()
               if k not in ("diverged", "failed")]
    handles.append(Patch(facecolor="white", edgecolor="black", hatch="///", label="diverged (ranked last)"))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=9, frameon=False)
    fig.suptitle("Long-run conservation, ranked (top = keeps best); colour: what the separatrix distance δ "
                 "did; ✗ = does not keep what it declares", fontsize=10)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    save_png(fig, path, palette=False, dpi=_DPI)


def _separatrix_figure(res, view, path) -> bool:
    """δ(t) of every variant whose δ drifted, crossed or went away on a long run (not the runs that diverged:
    the bars show those); False when none did. Few lines, so each gets its own colour of a qualitative
    palette (tab20) and a dash pattern, named in one legend under the panels."""
    drifts = ("toward_intermediate", "away_from_intermediate", "crosses_separatrix")
    moved = [s.variant for s in view.long if any(r.get("verdict") in drifts for r in s.records.values())]
    if not moved:
        return False
    import matplotlib

    from reports.canvas import new_figure, save_png
    cmap = matplotlib.colormaps["tab20"]
    palette = [cmap(k) for k in range(cmap.N)]   # a qualitative palette: its 20 colours as given
    dashes = ("-", "--", "-.", ":")
    names = view.long_runs
    rows = math.ceil(len(moved) / 3)
    legend_in = 0.3 + 0.24 * rows
    height = 3.8 + legend_in
    fig = new_figure((13.0, height), dpi=_DPI)
    axes = fig.subplots(1, len(names), squeeze=False)
    for ax, name in zip(axes[0], names):
        ser = res.series(name)
        for k, v in enumerate(moved):
            d = ser.get(v)
            rec = next((s.records.get(name) for s in view.long if s.variant == v), None) or {}
            if not d or "separatrix" not in d or rec.get("status") != "ok":
                continue
            ax.plot(d["t_s"], d["separatrix"], color=palette[(2 * k) % 20 + (k // 10) % 2],
                    ls=dashes[k % len(dashes)], lw=1.6, label=v)
        ax.axhline(0.0, color="#555555", lw=0.8, ls=":")
        ax.set_title(f"{name}: δ(t)", fontsize=10)
        ax.set_xlabel("t (s)")
        ax.set_ylim(-0.4, 1.05)
        ax.grid(color="#eeeeee")
    axes[0][0].set_ylabel("δ = (2E I₂ − |L|²)/|L|²\n(0: the separatrix)")
    handles, labels = [], []
    for ax in axes[0]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=9, frameon=False,
               bbox_to_anchor=(0.5, 0.0))
    fig.suptitle("δ(t) of the variants whose δ drifted (runs that diverged: see the bars); δ = −1/3: a "
                 "major-axis spin, ≈ +1: a minor-axis spin, 0: the separatrix", fontsize=10)
    fig.tight_layout(rect=(0, legend_in / height, 1, 1))
    save_png(fig, path, palette=False, dpi=_DPI)
    return True
