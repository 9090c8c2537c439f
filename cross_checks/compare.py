"""``rbcheck compare BASELINE_DIR NEW_DIR``: direction-aware regression check of two results directories.

Rows of ``results.csv`` are matched by (scenario, engine, dt). Each metric has a direction and an
absolute + relative tolerance (``METRIC_RULES``): errors and drifts are better when lower; a value
is a regression when ``new > old + abs_tol + rel_tol·|old|``, an improvement when
``new < old − abs_tol − rel_tol·|old|``. A status change away from ``ok`` is a regression.
Convergence records of ``summary.json`` are matched by (scenario, engine, quantity): an order that
moves further from its expected value by more than ``ORDER_TOL`` or a verdict that changes from
``converges`` is a regression. Engine versions of both provenances are compared and reported.

Exit codes: 0 no regression; 1 regression (or missing rows, unless allowed); 2 unusable input.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

__all__ = ["compare_dirs", "Comparison", "CompareInputError", "METRIC_RULES", "ORDER_TOL", "to_markdown"]

KEY = ["scenario", "engine", "dt"]

#: metric column -> (abs_tol, rel_tol). All are "lower is better".
#: rel 5 %: the same code on another machine reproduces errors to ~1e-12 relative (libm/BLAS
#: rounding, amplified by at most ~1e3 on the chaotic tumbling cases), while a real change of
#: scheme, default or force semantics changes errors by factors; 5 % separates the two with margin.
#: abs 1e-12: errors at the round-off floor (≤ 1e-12) fluctuate by O(1) factors and mean nothing.
METRIC_RULES = {
    "pos_err_final": (1e-12, 0.05),
    "vel_err_final": (1e-12, 0.05),
    "orient_err_final": (1e-12, 0.05),
    "angvel_err_final": (1e-12, 0.05),
    "pos_err_max": (1e-12, 0.05),
    "vel_err_max": (1e-12, 0.05),
    "orient_err_max": (1e-12, 0.05),
    "angvel_err_max": (1e-12, 0.05),
    "energy_drift_max": (1e-12, 0.05),
    "angmom_drift_max": (1e-12, 0.05),
    "linmom_drift_max": (1e-12, 0.05),
}
#: An observed order may move this much (in either direction) before it counts: the fitted order of
#: a ladder changes by ~0.01 between machines; 0.1 is the tolerance of the order tests (issue 2).
ORDER_TOL = 0.1
GOOD_VERDICTS = ("converges", "at_roundoff")
#: No claim on the ladder: a change to or from it is information, never a regression or improvement.
NEUTRAL_VERDICTS = ("pre_asymptotic",)


class CompareInputError(ValueError):
    """A results directory that cannot be compared (message names the file and the reason)."""


@dataclass
class Change:
    kind: str          # regression | improvement | new | missing | changed (informational)
    scenario: str
    engine: str
    what: str          # dt=... metric, or quantity
    old: str = ""
    new: str = ""
    note: str = ""


@dataclass
class Comparison:
    changes: list = field(default_factory=list)
    version_diffs: list = field(default_factory=list)  # (package, old, new)
    matched_rows: int = 0

    def of(self, kind):
        return [c for c in self.changes if c.kind == kind]

    def exit_code(self, allow_missing: bool = False) -> int:
        if self.of("regression") or (self.of("missing") and not allow_missing):
            return 1
        return 0


def _read_dir(d: Path):
    d = Path(d)
    if not d.is_dir():
        raise CompareInputError(f"{d}: not a directory")
    csv = d / "results.csv"
    if not csv.is_file():
        raise CompareInputError(f"{csv}: missing (is {d} a results directory written by `rbcheck sweep`?)")
    try:
        df = pd.read_csv(csv)
    except Exception as exc:  # pandas raises many kinds; all mean "unusable"
        raise CompareInputError(f"{csv}: cannot parse: {exc}") from None
    missing = [c for c in KEY + ["status"] if c not in df.columns]
    if missing:
        raise CompareInputError(f"{csv}: columns {', '.join(missing)} missing")
    if df.duplicated(KEY).any():
        dup = df[df.duplicated(KEY)].iloc[0]
        raise CompareInputError(f"{csv}: duplicate row for {dup['scenario']}, {dup['engine']}, dt={dup['dt']}")
    summary = {}
    sj = d / "summary.json"
    if sj.is_file():
        try:
            summary = json.loads(sj.read_text(encoding="utf-8"))
        except ValueError as exc:
            raise CompareInputError(f"{sj}: cannot parse JSON: {exc}") from None
    return df, summary


def _fmt(v):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def _expected_order(rec):
    if rec.get("expected_order") is not None:
        return float(rec["expected_order"])
    try:
        from .expectations import expected_order
        return expected_order(rec["engine"], rec["quantity"], rec.get("scenario"))
    except Exception:
        return None


def compare_dirs(baseline_dir, new_dir) -> Comparison:
    old_df, old_sum = _read_dir(Path(baseline_dir))
    new_df, new_sum = _read_dir(Path(new_dir))
    out = Comparison()
    for df in (old_df, new_df):
        df["dt"] = df["dt"].astype(float)
    merged = old_df.merge(new_df, on=KEY, how="outer", suffixes=("_old", "_new"), indicator=True)
    for _, r in merged.iterrows():
        where = f"dt={r['dt']:g}"
        if r["_merge"] == "left_only":
            out.changes.append(Change("missing", r["scenario"], r["engine"], where, note="row absent from the new results"))
            continue
        if r["_merge"] == "right_only":
            out.changes.append(Change("new", r["scenario"], r["engine"], where, new=str(r["status_new"])))
            continue
        out.matched_rows += 1
        so, sn = str(r["status_old"]), str(r["status_new"])
        if so != sn:
            kind = "regression" if so == "ok" else ("improvement" if sn == "ok" else "regression")
            out.changes.append(Change(kind, r["scenario"], r["engine"], f"{where} status", so, sn))
            continue
        for metric, (abs_tol, rel_tol) in METRIC_RULES.items():
            co, cn = f"{metric}_old", f"{metric}_new"
            if co not in merged.columns or cn not in merged.columns:
                continue
            vo, vn = r[co], r[cn]
            if pd.isna(vo) and pd.isna(vn):
                continue
            if pd.isna(vo) or pd.isna(vn):
                out.changes.append(Change("regression" if pd.isna(vn) else "improvement", r["scenario"], r["engine"],
                                          f"{where} {metric}", _fmt(vo), _fmt(vn), "value appeared/disappeared"))
                continue
            vo, vn = float(vo), float(vn)
            margin = abs_tol + rel_tol * abs(vo)
            if vn > vo + margin:
                out.changes.append(Change("regression", r["scenario"], r["engine"], f"{where} {metric}",
                                          _fmt(vo), _fmt(vn), f"×{vn / vo:.3g}" if vo else "was 0"))
            elif vn < vo - margin:
                out.changes.append(Change("improvement", r["scenario"], r["engine"], f"{where} {metric}",
                                          _fmt(vo), _fmt(vn), f"×{vn / vo:.3g}" if vo else ""))
    _compare_convergence(old_sum.get("convergence", []), new_sum.get("convergence", []), out)
    _compare_versions(old_sum.get("provenance", {}), new_sum.get("provenance", {}), out)
    return out


def _compare_convergence(old_recs, new_recs, out: Comparison):
    key = lambda rec: (rec["scenario"], rec["engine"], rec["quantity"])  # noqa: E731
    old = {key(r): r for r in old_recs}
    new = {key(r): r for r in new_recs}
    for k in sorted(set(old) | set(new)):
        scen, eng, qty = k
        if k not in new:
            out.changes.append(Change("missing", scen, eng, f"order of {qty}", note="convergence record absent"))
            continue
        if k not in old:
            out.changes.append(Change("new", scen, eng, f"order of {qty}", new=_fmt(new[k].get("order"))))
            continue
        ro, rn = old[k], new[k]
        vo, vn = ro.get("verdict"), rn.get("verdict")
        if vo != vn:
            if vo in NEUTRAL_VERDICTS or vn in NEUTRAL_VERDICTS:
                kind = "changed"  # a claim appears or disappears: information
            elif vo in GOOD_VERDICTS and vn not in GOOD_VERDICTS:
                kind = "regression"
            elif vn in GOOD_VERDICTS and vo not in GOOD_VERDICTS:
                kind = "improvement"
            elif vo in GOOD_VERDICTS and vn in GOOD_VERDICTS:
                kind = "changed"  # e.g. converges <-> at_roundoff: both say the scheme is right
            else:
                kind = "regression" if vn in ("diverged", "failed") else "improvement" if vo in ("diverged", "failed") else "regression"
            out.changes.append(Change(kind, scen, eng, f"verdict of {qty}", str(vo), str(vn)))
            continue
        oo, on = ro.get("order"), rn.get("order")
        exp = _expected_order(rn)
        if oo is None or on is None or exp is None or any(isinstance(v, float) and math.isnan(v) for v in (oo, on)):
            continue
        do, dn = abs(float(oo) - exp), abs(float(on) - exp)
        if dn > do + ORDER_TOL:
            out.changes.append(Change("regression", scen, eng, f"order of {qty}", _fmt(float(oo)), _fmt(float(on)),
                                      f"expected {exp:g}"))
        elif dn < do - ORDER_TOL:
            out.changes.append(Change("improvement", scen, eng, f"order of {qty}", _fmt(float(oo)), _fmt(float(on)),
                                      f"expected {exp:g}"))


def _versions(prov):
    v = prov.get("versions", prov)
    return {k: str(val) for k, val in v.items() if k in ("rbcheck", "numpy", "scipy", "mujoco", "pybullet", "python")}


def _compare_versions(po, pn, out: Comparison):
    vo, vn = _versions(po), _versions(pn)
    for k in sorted(set(vo) | set(vn)):
        if vo.get(k) != vn.get(k):
            out.version_diffs.append((k, vo.get(k, "—"), vn.get(k, "—")))


def to_text(c: Comparison, allow_missing=False) -> str:
    lines = [f"compared {c.matched_rows} matching rows: {len(c.of('regression'))} regressions, "
             f"{len(c.of('improvement'))} improvements, {len(c.of('new'))} new, {len(c.of('missing'))} missing"]
    for pkg, a, b in c.version_diffs:
        lines.append(f"  version of {pkg}: {a} -> {b}")
    for kind in ("regression", "missing", "improvement", "new", "changed"):
        for ch in c.of(kind):
            lines.append(f"  {kind.upper():<11} {ch.scenario} {ch.engine} {ch.what}: {ch.old} -> {ch.new} {ch.note}".rstrip())
    verdict = {0: "OK: no regression", 1: "REGRESSION"}[c.exit_code(allow_missing)]
    lines.append(verdict)
    return "\n".join(lines)


def _md_escape(s: str) -> str:
    return str(s).replace("|", "\\|").replace("\n", " ").replace("<", "&lt;").replace(">", "&gt;")


def to_markdown(c: Comparison, baseline_dir, new_dir, allow_missing=False) -> str:
    code = c.exit_code(allow_missing)
    head = "✅ no regression" if code == 0 else "❌ regression"
    md = [f"## rbcheck compare: {head}", "",
          f"Baseline `{_md_escape(baseline_dir)}` vs new `{_md_escape(new_dir)}`: {c.matched_rows} matching rows, "
          f"**{len(c.of('regression'))} regressions**, {len(c.of('improvement'))} improvements, "
          f"{len(c.of('new'))} new, {len(c.of('missing'))} missing.", ""]
    if c.version_diffs:
        md += ["### Version differences", "", "| package | baseline | new |", "|---|---|---|"]
        md += [f"| {_md_escape(p)} | {_md_escape(a)} | {_md_escape(b)} |" for p, a, b in c.version_diffs]
        md.append("")
    for kind, title in (("regression", "Regressions"), ("missing", "Missing rows"), ("improvement", "Improvements"),
                        ("new", "New rows"), ("changed", "Other changes (not regressions)")):
        rows = c.of(kind)
        if not rows:
            continue
        md += [f"### {title}", "", "| scenario | engine | what | baseline | new | note |", "|---|---|---|---|---|---|"]
        md += [f"| {_md_escape(r.scenario)} | {_md_escape(r.engine)} | {_md_escape(r.what)} | {_md_escape(r.old)} | "
               f"{_md_escape(r.new)} | {_md_escape(r.note)} |" for r in rows]
        md.append("")
    return "\n".join(md)
