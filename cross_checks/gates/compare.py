"""``rbcheck compare BASELINE_DIR NEW_DIR``: direction-aware regression check of two results directories.

Rows of ``results.csv`` are matched by (scenario, engine, dt), convergence records by (scenario, engine,
quantity). Each metric has a direction and an absolute + relative tolerance (``METRIC_RULES``): a value is
a regression when ``new > old + abs_tol + rel_tol·|old|``, an improvement when
``new < old − abs_tol − rel_tol·|old|``; a status change away from ``ok``, an order further from its
expected value by more than ``ORDER_TOL``, or a verdict that changes from ``converges`` is a regression.

Either side may be a full results directory or a compact baseline; both are validated in full first
(damaged input is exit 2 with one line, never "no regression": docs/hardening.md, "compare"). A sweep
of a subset is compared on what it ran (the rest counted as NOT COMPARED in one line); a variant it
skipped as unavailable is missing. Verdicts per variant and the output: docs/results.md, "Comparing two
results directories".

Exit codes: 0 no regression; 1 regression (or missing rows, unless allowed); 2 unusable input.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from cross_checks.core.tolerances import (
    COMPARE_ABS_TOL,
    COMPARE_REL_TOL,
    COMPARE_SCHEME_CHANGE_MAX_RATIO,
    ORDER_TOL,
)
from cross_checks.sweep import reader
from cross_checks.sweep.reader import REQUIRED_COLUMNS, ResultsReadError

__all__ = ["compare_dirs", "read_results_dir", "Comparison", "CompareInputError", "METRIC_RULES", "ORDER_TOL",
           "VariantChange", "variant_changes",
           "REQUIRED_COLUMNS", "Scope", "not_compared", "not_installed_lines", "not_installed_sentence",
           "verdict_line",
           "to_markdown", "to_text"]

KEY = list(reader.KEY)

#: metric column -> (abs_tol, rel_tol), from cross_checks/core/tolerances.py (their derivation is
#: there). All are "lower is better". An order is compared within ORDER_TOL (the order studies' tolerance).
METRIC_RULES = {m: (COMPARE_ABS_TOL, COMPARE_REL_TOL) for m in (
    "pos_err_final", "vel_err_final", "orient_err_final", "angvel_err_final",
    "pos_err_max", "vel_err_max", "orient_err_max", "angvel_err_max",
    "energy_drift_max", "angmom_drift_max", "linmom_drift_max")}
GOOD_VERDICTS = ("converges", "at_roundoff")
#: No claim on the ladder: a change to or from it is information, never a regression or improvement.
NEUTRAL_VERDICTS = ("pre_asymptotic",)


class CompareInputError(ValueError):
    """A results directory that cannot be compared (message names the file and the reason)."""


@dataclass
class Change:
    kind: str          # regression | improvement | new | missing | changed (informational) | contradiction
    #                    (a record with nothing to compare with whose own verdict contradicts its declaration)
    scenario: str
    engine: str
    what: str          # dt=... metric, or quantity
    old: str = ""
    new: str = ""
    note: str = ""
    area: str = "row"  # row (a metric or status) | order | local order | agreement | energy kind | engine
    #                    | contradiction
    ratio: float | None = None   # new / old of a metric that moved


@dataclass
class VariantChange:
    """What changed for one engine variant, judged as a whole (:func:`variant_changes`).

    category : "regression", "improvement", "scheme changed" (errors moved both ways within
        COMPARE_SCHEME_CHANGE_MAX_RATIO), "changed" (information only), "missing", "new" (only in the new
        results, every verdict as declared) or "contradiction" (new, and a verdict contradicts its
        declaration) (docs/results.md, "Comparing two results directories").
    causes : the explaining facts first — verdicts and fitted orders, one-step orders, agreement with the
        same-scheme variant, energy-drift kind — one sentence each, at most a few.
    ratio_range : (lowest, highest) new/old over the metric changes; rows, scenarios : how many moved.
    """

    variant: str
    category: str
    causes: list
    ratio_range: tuple | None
    rows: int
    scenarios: list


@dataclass
class Scope:
    """What the new results ran (None: everything, e.g. a summary that does not list it): the
    baseline rows and records outside it are not compared, only counted. A variant of an OPTIONAL engine
    that is simply not installed where the new results were made (``not_installed``) is outside it too,
    counted per engine, unless that engine is ``required`` (``--require``)."""

    scenarios: frozenset | None = None
    variants: frozenset | None = None
    unavailable: dict = field(default_factory=dict)  # variant -> why the new sweep skipped it (rows missing)
    not_installed: dict = field(default_factory=dict)  # variant of an optional engine not installed -> why
    required: frozenset = frozenset()                   # engines whose absence is a failure (--require)
    skipped_rows: int = 0
    skipped_records: int = 0
    skipped_scenarios: set = field(default_factory=set)
    skipped_variants: set = field(default_factory=set)
    absent_rows: dict = field(default_factory=dict)     # engine not installed -> baseline rows not compared
    absent_records: dict = field(default_factory=dict)  # engine not installed -> records not compared
    inexpressible: dict = field(default_factory=dict)   # (scenario, variant) its engine cannot take -> why

    def missing_note(self, scenario: str, engine: str, default: str) -> str:
        """Why the new results lack a (scenario, variant) the baseline has: its engine cannot express the
        scenario now, or the variant was unavailable, else ``default``."""
        why = self.inexpressible.get((scenario, engine))
        if why:
            return f"not expressible by its engine in the new results: {why}"
        why = self.unavailable.get(engine) or self.not_installed.get(engine)
        return f"variant unavailable in the new sweep: {why}" if why else default

    def absent(self, engine: str) -> bool:
        """Whether ``engine`` (a variant) belongs to an optional engine not installed in the new results,
        and no --require insists on it."""
        return engine in self.not_installed and engine.split(":", 1)[0] not in self.required

    def ran(self, scenario: str, engine: str) -> bool:
        """Whether the new results ran this (scenario, variant), or were meant to (an unavailable variant,
        or one of an engine --require names)."""
        if self.scenarios is not None and scenario not in self.scenarios:
            return False
        if self.absent(engine):
            return False
        return (self.variants is None or engine in self.variants or engine in self.unavailable
                or engine in self.not_installed)

    def skip(self, scenario: str, engine: str, record: bool = False) -> None:
        if self.absent(engine) and (self.scenarios is None or scenario in self.scenarios):
            counts = self.absent_records if record else self.absent_rows
            name = engine.split(":", 1)[0]
            counts[name] = counts.get(name, 0) + 1
            return
        if record:
            self.skipped_records += 1
        else:
            self.skipped_rows += 1
        if self.scenarios is not None and scenario not in self.scenarios:
            self.skipped_scenarios.add(scenario)
        else:
            self.skipped_variants.add(engine)


@dataclass
class Comparison:
    changes: list = field(default_factory=list)
    version_diffs: list = field(default_factory=list)  # (package, old, new)
    matched_rows: int = 0
    scope: Scope = field(default_factory=Scope)

    def of(self, kind):
        return [c for c in self.changes if c.kind == kind]

    def exit_code(self, allow_missing: bool = False, fail_on_change: bool = False) -> int:
        """1 on a regression of any variant (and on rows missing, unless allowed); with ``fail_on_change``
        on any change at all, improvements and changed schemes included (a stale baseline); else 0."""
        cats = {v.category for v in variant_changes(self)}
        overall = any(ch.engine == "(all)" for ch in self.of("regression"))   # a metric column gone
        if {"regression", "contradiction"} & cats or overall or (self.of("missing") and not allow_missing):
            return 1
        if fail_on_change and (self.changes or self.version_diffs):
            return 1
        return 0


def read_results_dir(d: Path):
    """``(results.csv as a DataFrame of the columns compare reads, summary.json)`` of a results directory
    or a compact baseline, validated in full by the one reader of a results directory
    (cross_checks.sweep.reader; CompareInputError naming the file, the field and the reason)."""
    try:
        got = reader.read_results_dir(d)
    except ResultsReadError as exc:
        raise CompareInputError(str(exc)) from None
    cols = got.table.columns
    df = got.table.frame(["scenario", "engine", "dt", "status", *[m for m in METRIC_RULES if m in cols],
                          *(["energy_drift_kind"] if "energy_drift_kind" in cols else [])])
    if "energy_drift_kind" in cols:
        strip = (lambda v: v.strip() if isinstance(v, str) else v)   # an empty table's column is float
        df["energy_drift_kind"] = df["energy_drift_kind"].map(strip)
    return df, got.summary


def _fmt(v):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def _expected_order(rec):
    """The order a record should show: its own ``expected_order``, else what the expectations say of
    its variant (None for a variant they do not know, e.g. an engine file no longer registered)."""
    if rec.get("expected_order") is not None:
        return float(rec["expected_order"])
    try:
        from cross_checks.analysis.expectations import expected_order
        from cross_checks.engines import resolve
        # a name read from a results directory: resolved here, the cautious defaults for one nobody declares
        return expected_order(resolve(rec["engine"]), rec["quantity"], rec.get("scenario"))
    except Exception:  # noqa: BLE001 - an unknown variant has no expected order
        return None


def compare_dirs(baseline_dir, new_dir, require=()) -> Comparison:
    """Every difference between two results directories (or compact baselines), each judged. ``require``:
    engines that must have run in ``new_dir`` (an optional engine absent there is then a failure, not
    rows left uncompared)."""
    old_df, old_sum = read_results_dir(Path(baseline_dir))
    new_df, new_sum = read_results_dir(Path(new_dir))
    out = Comparison(scope=_scope(new_sum, frozenset(require)))
    _check_required(new_sum, out)
    _compare_columns(old_df, new_df, out)
    _compare_rows(old_df.merge(new_df, on=KEY, how="outer", suffixes=("_old", "_new"), indicator=True), out)
    _compare_convergence(old_sum.get("convergence", []), new_sum.get("convergence", []), out)
    _compare_convergence(old_sum.get("local_convergence", []), new_sum.get("local_convergence", []), out,
                         local=True)
    _compare_agreement(old_sum.get("agreement", []), new_sum.get("agreement", []), out)
    _compare_invariance(old_sum.get("invariance"), new_sum.get("invariance"), out)
    _compare_declared(old_sum.get("invariance_declared"), new_sum.get("invariance_declared"), out)
    _compare_versions(old_sum.get("provenance", {}), new_sum.get("provenance", {}), out)
    return out


def _scope(summary: dict, required: frozenset = frozenset()) -> Scope:
    """What a results directory's sweep ran, from its summary.json (everything when it does not say)."""
    skipped = summary.get("skipped_variants") or []
    optional_absent = {v["name"]: v["reason"] for v in skipped
                       if v.get("installed") is False and v.get("required") is False}
    broken = {v["name"]: v["reason"] for v in skipped if v["name"] not in optional_absent}
    cannot = {(r["scenario"], r["engine"]): r["reason"] for r in summary.get("not_expressible") or []}
    if not isinstance(summary.get("scenarios"), list) or not isinstance(summary.get("variants"), list):
        return Scope(unavailable=broken, not_installed=optional_absent, required=required,
                     inexpressible=cannot)
    return Scope(frozenset(s["name"] for s in summary["scenarios"]),
                 frozenset(v["name"] for v in summary["variants"]), broken, optional_absent, required,
                 inexpressible=cannot)


def _check_required(new_sum: dict, out: Comparison) -> None:
    """A --require'd engine none of whose variants the new results ran or skipped is a failure on its own."""
    known = [v["name"] for v in (new_sum.get("variants") or []) + (new_sum.get("skipped_variants") or [])]
    for engine in sorted(out.scope.required):
        if not any(n.split(":", 1)[0] == engine for n in known):
            out.changes.append(Change("missing", "(all)", f"{engine}:*", "engine",
                                      note=f"--require {engine}: the new results ran none of its variants"))


def _compare_columns(old_df, new_df, out: Comparison):
    for metric in METRIC_RULES:  # a metric the baseline has and the new results lack cannot pass
        if metric in old_df.columns and metric not in new_df.columns:
            out.changes.append(Change("regression", "(all)", "(all)", f"column {metric}",
                                      note="metric missing from the new results.csv"))
        elif metric in new_df.columns and metric not in old_df.columns:
            out.changes.append(Change("new", "(all)", "(all)", f"column {metric}",
                                      note="metric new in these results"))


def _compare_rows(merged, out: Comparison):
    """Rows matched by (scenario, engine, dt): missing, new, a status change, or each metric judged."""
    for _, r in merged.iterrows():
        where = f"dt={r['dt']:g}"
        if r["_merge"] == "left_only":
            if not out.scope.ran(r["scenario"], r["engine"]):
                out.scope.skip(r["scenario"], r["engine"])
                continue
            note = out.scope.missing_note(r["scenario"], r["engine"], "row absent from the new results")
            out.changes.append(Change("missing", r["scenario"], r["engine"], where, note=note))
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
            if co in merged.columns and cn in merged.columns:
                change = _metric_change(r[co], r[cn], abs_tol, rel_tol)
                if change is not None:
                    kind, old, new, note = change
                    ratio = (float(r[cn]) / float(r[co]) if not pd.isna(r[co]) and not pd.isna(r[cn])
                             and float(r[co]) > 0 else None)
                    out.changes.append(Change(kind, r["scenario"], r["engine"], f"{where} {metric}", old, new,
                                              note, ratio=ratio))
        ko, kn = r.get("energy_drift_kind_old"), r.get("energy_drift_kind_new")
        if isinstance(ko, str) and isinstance(kn, str) and ko and kn and ko != kn:
            out.changes.append(Change("changed", r["scenario"], r["engine"], f"{where} energy_drift_kind", ko,
                                      kn, area="energy kind"))


def _metric_change(vo, vn, abs_tol, rel_tol):
    """``(kind, old, new, note)`` when a lower-is-better metric moved beyond its tolerance, else None."""
    if pd.isna(vo) and pd.isna(vn):
        return None
    if pd.isna(vo) or pd.isna(vn):
        return (("regression" if pd.isna(vn) else "improvement"), _fmt(vo), _fmt(vn),
                "value appeared/disappeared")
    vo, vn = float(vo), float(vn)
    margin = abs_tol + rel_tol * abs(vo)
    if vn > vo + margin:
        return "regression", _fmt(vo), _fmt(vn), f"×{vn / vo:.3g}" if vo else "was 0"
    if vn < vo - margin:
        return "improvement", _fmt(vo), _fmt(vn), f"×{vn / vo:.3g}" if vo else ""
    return None


def _verdict_change_kind(vo, vn) -> str:
    """How a change of convergence verdict from ``vo`` to ``vn`` counts."""
    if vo in NEUTRAL_VERDICTS or vn in NEUTRAL_VERDICTS:
        return "changed"  # a claim appears or disappears: information
    if vo in GOOD_VERDICTS and vn not in GOOD_VERDICTS:
        return "regression"
    if vn in GOOD_VERDICTS and vo not in GOOD_VERDICTS:
        return "improvement"
    if vo in GOOD_VERDICTS and vn in GOOD_VERDICTS:
        return "changed"  # e.g. converges <-> at_roundoff: both say the scheme is right
    if vn in ("diverged", "failed"):
        return "regression"
    return "improvement" if vo in ("diverged", "failed") else "regression"


def _compare_convergence(old_recs, new_recs, out: Comparison, local: bool = False):
    """Convergence records (``local``: the one-step ones) matched by (scenario, engine, quantity): missing,
    new, a verdict change, or the order judged (:func:`_order_change`)."""
    key = lambda rec: (rec["scenario"], rec["engine"], rec["quantity"])  # noqa: E731
    old = {key(r): r for r in old_recs}
    new = {key(r): r for r in new_recs}
    area, what = ("local order", "one-step order") if local else ("order", "order")
    for k in sorted(set(old) | set(new)):
        scen, eng, qty = k
        if k not in new:
            if not out.scope.ran(scen, eng):
                if not local:
                    out.scope.skip(scen, eng, record=True)
                continue
            if local:
                continue  # a one-step record absent: its engine lost its one-step mode; the rows say the rest
            out.changes.append(Change("missing", scen, eng, f"order of {qty}",
                                      note=out.scope.missing_note(scen, eng, "convergence record absent")))
        elif k not in old:
            out.changes.append(Change("new", scen, eng, f"{what} of {qty}",
                                      new=_fmt(new[k].get("order")), area=area))
            if not local and new[k].get("matches_expectation") is False:
                # nothing to compare it with, but its own verdict contradicts what its variant declares:
                # a broken new variant (or scenario) must not pass the gate as "new"
                out.changes.append(Change("contradiction", scen, eng, f"verdict of {qty}",
                                          new=str(new[k].get("verdict")),
                                          note=str(new[k].get("assessment") or "not as expected"),
                                          area="contradiction"))
        elif old[k].get("verdict") != new[k].get("verdict"):
            vo, vn = old[k].get("verdict"), new[k].get("verdict")
            out.changes.append(Change(_verdict_change_kind(vo, vn), scen, eng,
                                      f"{'one-step ' if local else ''}verdict "
                                      f"of {qty}", str(vo), str(vn), area=area))
        else:
            change = _order_change(old[k], new[k])
            if change is not None:
                kind, old_order, new_order, note = change
                out.changes.append(Change(kind, scen, eng, f"{what} of {qty}",
                                          old_order, new_order, note, area=area))


def _compare_agreement(old_recs, new_recs, out: Comparison):
    """Agreement of same-scheme variant pairs, matched by (a, b, scenario): a pair that agreed and no longer
    does is a regression of both; the reverse an improvement."""
    key = lambda rec: (rec["a"], rec["b"], rec["scenario"])  # noqa: E731
    old = {key(r): r for r in old_recs}
    new = {key(r): r for r in new_recs}
    for k in sorted(set(old) & set(new)):
        ao, an = bool(old[k].get("agrees")), bool(new[k].get("agrees"))
        if ao == an:
            continue
        kind = "regression" if ao else "improvement"
        for eng, other in ((k[0], k[1]), (k[1], k[0])):
            out.changes.append(Change(kind, k[2], eng, f"agreement with {other}",
                                      "agrees" if ao else "differs", "agrees" if an else "differs",
                                      area="agreement"))


def _compare_invariance(old_recs, new_recs, out: Comparison):
    """Invariance checks (summary.json ``invariance``: the checks that do not hold), matched by (scenario,
    engine, transform, magnitude): a broken invariance the baseline does not have broken is a regression
    (whether the baseline held it, declared it as a known finding, or did not run the checks:
    docs/invariance.md); one broken or a known finding there and neither here is an improvement ("no longer
    broken"), as is a broken one that is now a declared known finding.
    Without the checks in the new results nothing is compared."""
    if new_recs is None:
        return
    key = lambda r: (r["scenario"], r["engine"], r["transform"], r["magnitude"])  # noqa: E731
    old = {key(r): r for r in old_recs or []}
    new = {key(r): r for r in new_recs}

    def verdict(recs, k, ran):
        return recs[k]["verdict"] if k in recs else ("holds" if ran else "not run")

    for k in sorted(set(old) | set(new)):
        before, after = verdict(old, k, old_recs is not None), verdict(new, k, True)
        bad = ("broken", "known finding")
        if after == "broken" and before != "broken":
            kind, note = "regression", new[k]["assessment"]
        elif before == "broken" and after != "broken" or (before == "known finding" and after not in bad):
            kind = "improvement"
            note = (new[k]["assessment"] if after == "known finding"
                    else f"no longer broken: {old[k]['assessment']}")
        else:
            continue
        out.changes.append(Change(kind, k[0], k[1], f"invariance under {k[2]} {k[3]}", before, after,
                                  note=note, area="invariance"))


def _compare_declared(old_recs, new_recs, out: Comparison):
    """Declared invariance findings (summary.json ``invariance_declared``), matched by (engine, transform): a
    known finding there that broke on none of its checks here is an improvement ("no longer broken")."""
    old = {(d["engine"], d["transform"]): d for d in old_recs or []}
    for d in new_recs or []:
        before = old.get((d["engine"], d["transform"]))
        if before and before["verdict"] == "known finding" and d["verdict"] == "no longer broken":
            out.changes.append(Change("improvement", "(every scenario)", d["engine"],
                                      f"declared invariance finding under {d['transform']}", "known finding",
                                      "no longer broken", area="invariance",
                                      note=f"broke on none of the {d['checks']} check(s) it covers"))


def _order_change(ro, rn):
    """``(kind, old, new, note)`` when the order of a record whose verdict did not change moved, else None."""
    oo, on = ro.get("order"), rn.get("order")
    if oo is None and on is None:
        return None
    if oo is None or on is None:  # an order that appeared or vanished under the same verdict
        note = "no order fitted" if on is None else "order now fitted"
        return ("regression" if on is None else "changed"), _fmt(oo), _fmt(on), note
    exp = _expected_order(rn)
    if exp is None:  # no expected order: a converging order that moves beyond the tolerance is a
        # regression (nothing says which way is better); the order of a record that does not converge
        # measures no scheme and is not compared
        if rn.get("verdict") in GOOD_VERDICTS and abs(float(on) - float(oo)) > ORDER_TOL:
            return "regression", _fmt(float(oo)), _fmt(float(on)), "no expected order to judge the change by"
        return None
    do, dn = abs(float(oo) - exp), abs(float(on) - exp)
    if dn > do + ORDER_TOL:
        return "regression", _fmt(float(oo)), _fmt(float(on)), f"expected {exp:g}"
    if dn < do - ORDER_TOL:
        return "improvement", _fmt(float(oo)), _fmt(float(on)), f"expected {exp:g}"
    return None


def _versions(prov):
    v = prov.get("versions", prov)
    out = {k: str(val)
           for k, val in v.items() if k in ("rbcheck", "numpy", "scipy", "mujoco", "pybullet", "python")}
    for name, e in (prov.get("engines") or {}).items():  # user engines: version, and an engine file's hash
        if name not in out and isinstance(e, dict):
            sha = e.get("engine_file_sha256")
            progs = "".join(sorted((e.get("programs_sha256") or {}).values()))
            progs = hashlib.sha256(progs.encode()).hexdigest()[:12] if progs else ""
            out[f"engine {name}"] = (str(e.get("version", "")) + (f" (engine file {sha[:12]}" if sha else "")
                                     + (f", programs {progs}" if progs else "") + (")" if sha else ""))
    return out


def _compare_versions(po, pn, out: Comparison):
    vo, vn = _versions(po), _versions(pn)
    for k in sorted(set(vo) | set(vn)):
        if k.startswith("engine ") and (k not in vo or k not in vn):
            continue   # an engine only one side ran: its rows are new or not compared, not a version change
        if vo.get(k) != vn.get(k):
            out.version_diffs.append((k, vo.get(k, "—"), vn.get(k, "—")))


_CAUSE_AREAS = ("order", "local order", "agreement", "energy kind", "invariance")


def variant_changes(c: Comparison) -> list:
    """Every variant that changed, judged as a whole (:class:`VariantChange`), regressions first."""
    by = {}
    for ch in c.changes:
        if ch.engine.endswith(":*") or ch.engine == "(all)":
            continue
        by.setdefault(ch.engine, []).append(ch)
    out = [_variant_change(v, chs) for v, chs in by.items()]
    rank = {"contradiction": 0, "regression": 1, "missing": 2, "scheme changed": 3, "improvement": 4,
            "new": 5, "changed": 6}
    return sorted(out, key=lambda v: (rank[v.category], v.variant))


def _variant_change(variant: str, chs: list) -> VariantChange:
    rows = [ch for ch in chs if ch.area == "row" and ch.kind in ("regression", "improvement")]
    ratios = [ch.ratio for ch in rows if ch.ratio is not None and ch.ratio > 0]
    explained = [ch for ch in chs if ch.area in _CAUSE_AREAS or (ch.area == "row" and "status" in ch.what)]
    kinds = {ch.kind for ch in explained if ch.kind != "changed"}
    worse, better = ([ch for ch in rows if ch.kind == "regression"],
                     [ch for ch in rows if ch.kind == "improvement"])
    contradictions = [ch for ch in chs if ch.kind == "contradiction"]
    if contradictions:   # its verdicts say it is broken, whatever else moved
        causes = [f"{ch.what.removeprefix('verdict of ').replace('_', ' ')} on {ch.scenario}: {ch.note}"
                  for ch in contradictions]
        return VariantChange(variant, "contradiction", causes, None, len(rows),
                             sorted({ch.scenario for ch in contradictions}))
    if all(ch.kind == "new" for ch in chs):   # nothing to compare with, and none of its verdicts contradicts
        scen = sorted({ch.scenario for ch in chs})
        why = (f"new in these results on {len(scen)} scenario(s) ({_names(scen, 3)}): no verdict "
               "contradicts what it declares")
        return VariantChange(variant, "new", [why], None, 0, scen)
    if any(ch.kind == "missing" for ch in chs):
        category = "missing"
    elif "regression" in kinds:
        category = "regression"
    elif "improvement" in kinds:
        category = "improvement"
    elif worse and better:
        too_much = any(ch.ratio is None or ch.ratio > COMPARE_SCHEME_CHANGE_MAX_RATIO for ch in worse)
        category = "regression" if too_much else "scheme changed"
    elif worse:
        category = "regression"
    elif better:
        category = "improvement"
    else:
        category = "changed"
    causes = _causes(explained)
    return VariantChange(variant, category, causes, (min(ratios), max(ratios)) if ratios else None, len(rows),
                         sorted({ch.scenario for ch in rows}))


def _causes(explained) -> list:
    """The facts that explain a variant's change, one sentence per (area, quantity), with the scenarios they
    hold on: "orientation order 3.95–4.03 -> 2.00 on 5 scenarios (applied_torque, …; expected 4)"."""
    merged = {}
    for ch in explained:
        merged.setdefault((ch.area, ch.what), []).append(ch)
    out = []
    order = {a: i for i, a in enumerate(("row",) + _CAUSE_AREAS)}
    for (area, what), chs in sorted(merged.items(), key=lambda kv: (order.get(kv[0][0], 9), kv[0][1])):
        scen = sorted({ch.scenario for ch in chs})
        where = f"{scen[0]}" if len(scen) == 1 else f"{len(scen)} scenarios ({_names(scen, 3)})"
        if area == "energy kind":
            where += f" ({len(chs)} row(s))"
        notes = sorted({ch.note for ch in chs if ch.note})
        label = _cause_label(area, what)
        text = f"{label} {_span([ch.old for ch in chs])} -> {_span([ch.new for ch in chs])} on {where}"
        out.append(" ".join(text.split()) + (f" ({'; '.join(notes)})" if notes else ""))
    return out


def _cause_label(area: str, what: str) -> str:
    """``orientation one-step order``, ``angular velocity verdict``, ``agreement with mujoco:euler``."""
    if " of " in what and area in ("order", "local order"):
        head, qty = what.rsplit(" of ", 1)
        return f"{qty.replace('_', ' ')} {head}"
    if area == "energy kind":
        return "energy-drift kind"
    return what.replace("_", " ")


def _span(values) -> str:
    """``3.95–4.03`` for numbers, the distinct words otherwise (``converges/does_not_converge``)."""
    nums = []
    for v in values:
        try:
            nums.append(float(v))
        except (TypeError, ValueError):
            return "/".join(dict.fromkeys(str(v) for v in values))
    lo, hi = min(nums), max(nums)
    return f"{lo:.2f}" if hi - lo < 0.005 else f"{lo:.2f}–{hi:.2f}"


def _ratio_text(v: VariantChange) -> str:
    if v.ratio_range is None:
        return "—"
    lo, hi = v.ratio_range
    span = f"×{lo:.3g}" if abs(hi - lo) <= 1e-12 * max(hi, 1.0) else f"×{lo:.3g} … ×{hi:.3g}"
    return f"{span} over {v.rows} row metric(s), {len(v.scenarios)} scenario(s)"


def _unchanged_variants(c: Comparison, new_variants) -> list:
    moved = {ch.engine for ch in c.changes}
    return sorted(v for v in new_variants if v not in moved)


def _names(items, at_most: int = 8) -> str:
    items = sorted(items)
    more = f" and {len(items) - at_most} more" if len(items) > at_most else ""
    return ", ".join(items[:at_most]) + more


def not_installed_lines(c: Comparison) -> list:
    """One sentence per optional engine that is not installed where the new results were made: how many
    baseline rows and records of it were not compared, and how to insist on it."""
    sc = c.scope
    out = []
    for engine in sorted(set(sc.absent_rows) | set(sc.absent_records)):
        out.append(f"{engine} not installed: {sc.absent_rows.get(engine, 0)} baseline rows "
                   f"and {sc.absent_records.get(engine, 0)} convergence records not compared "
                   f"(an optional engine; --require {engine} makes its absence a failure)")
    return out


def not_installed_sentence(c: Comparison) -> str:
    """All optional engines not installed where the new results were made, in one sentence ("" when none):
    the markdown's single paragraph for them."""
    sc = c.scope
    engines = sorted(set(sc.absent_rows) | set(sc.absent_records))
    if not engines:
        return ""
    each = ", ".join(f"{e} ({sc.absent_rows.get(e, 0)} baseline rows, {sc.absent_records.get(e, 0)} "
                     "convergence records)" for e in engines)
    return (f"Not compared: {len(engines)} optional engine(s) not installed where the new results were made "
            f"— {each}; --require ENGINE makes an absence a failure")


def not_compared(c: Comparison) -> str:
    """One sentence on the baseline rows and records of scenarios/variants the new results did not run
    ("" when there are none)."""
    sc = c.scope
    if not (sc.skipped_rows or sc.skipped_records):
        return ""
    what = []
    if sc.skipped_scenarios:
        what.append(f"{len(sc.skipped_scenarios)} scenario(s) ({_names(sc.skipped_scenarios)})")
    if sc.skipped_variants:
        what.append(f"{len(sc.skipped_variants)} variant(s) ({_names(sc.skipped_variants)})")
    return (f"not compared: {sc.skipped_rows} baseline row(s) and {sc.skipped_records} "
            f"convergence record(s) of {' and '.join(what)} the new results did not run")


def verdict_line(c: Comparison, allow_missing=False, fail_on_change=False) -> str:
    """What the exit code means, in words that agree with the counts."""
    vcs = variant_changes(c)
    reg = [v.variant for v in vcs if v.category == "regression"]
    reg += ["every variant"] * any(ch.engine == "(all)" for ch in c.of("regression"))
    n_miss = len(c.of("missing"))
    bad = [v for v in vcs if v.category == "contradiction"]
    if bad:   # new in these results, nothing to compare with: judged on their own verdicts
        n = len(c.of("contradiction"))
        also = f"; {len(reg)} variant(s) regressed ({_names(reg, 4)})" if reg else ""
        return (f"CONTRADICTION: {len(bad)} new variant(s) contradict what they declare "
                f"({_names([v.variant for v in bad], 4)}): {bad[0].variant}: {bad[0].causes[0]}"
                + (f"; {n} such verdict(s) in all" if n > 1 else "") + also
                + (f", {n_miss} missing" if n_miss else ""))
    if reg:
        return (f"REGRESSION: {len(reg)} variant(s) regressed ({_names(reg, 4)}); {len(c.of('regression'))} "
                "regression(s) in all" + (f", {n_miss} missing" if n_miss else ""))
    if n_miss and not allow_missing:
        return (f"MISSING: {n_miss} row(s) or record(s) of what the new results ran are absent from them "
                "(--allow-missing accepts that)")
    changed = [v for v in vcs if v.category in ("improvement", "scheme changed")]
    if changed or c.version_diffs:
        what = ", ".join(f"{v.variant} {v.category}" for v in changed[:4]) or "engine versions"
        stale = (f"OK: no regression, but the baseline is stale ({what}): regenerate it (baselines/README.md)"
                 if not fail_on_change else f"CHANGED: {what} (--fail-on-change)")
        return stale
    return "OK: no regression"


def summary_lines(c: Comparison, new_variants=(), allow_missing=False, fail_on_change=False) -> list:
    """The first screen: the verdict, the engine versions that changed, one line per changed variant (its
    category, its cause, its errors' ratio range), the variants that did not change."""
    lines = [verdict_line(c, allow_missing, fail_on_change)]
    if c.version_diffs:
        lines.append("versions changed: " + ", ".join(f"{p} {a} -> {b}" for p, a, b in c.version_diffs))
    for v in variant_changes(c):
        cause = "; ".join(v.causes[:3]) + (f"; and {len(v.causes) - 3} more" if len(v.causes) > 3 else "")
        lines.append(f"  {v.variant}: {v.category.upper()} — "
                     f"{cause or 'errors only'}; errors {_ratio_text(v)}")
    unchanged = _unchanged_variants(c, new_variants)
    if unchanged:
        lines.append(f"unchanged: {len(unchanged)} variant(s) ({_names(unchanged, 12)})")
    return lines


def to_text(c: Comparison, allow_missing=False, new_variants=(), fail_on_change=False) -> str:
    if not c.changes and not c.version_diffs:   # a rerun of the same code: one line (and what was left out)
        quiet = [f"OK: no regression: {c.matched_rows} matching rows compared, nothing changed"]
        return "\n".join(quiet + ([not_compared(c)] if not_compared(c) else []) + not_installed_lines(c))
    lines = [f"compared {c.matched_rows} matching rows: {_count(len(c.of('regression')), 'regression')}, "
             f"{_count(len(c.of('improvement')), 'improvement')}, "
             f"{len(c.of('new'))} new, {len(c.of('missing'))} missing"
             + (f"; {_count(len(c.of('contradiction')), 'new verdict')} contradicting "
                "what the variant declares" if c.of("contradiction") else "")]
    lines += summary_lines(c, new_variants, allow_missing, fail_on_change)[1:]
    if not_compared(c):
        lines.append(not_compared(c))
    lines += not_installed_lines(c)
    for pkg, a, b in c.version_diffs:
        lines.append(f"  version of {pkg}: {a} -> {b}")
    detail = [f"  {kind.upper():<11} {ch.scenario} {ch.engine} {ch.what}: "
              f"{ch.old} -> {ch.new} {ch.note}".rstrip()
              for kind in ("contradiction", "regression", "missing", "improvement", "new", "changed")
              for ch in c.of(kind)]
    if len(detail) > 40:   # the grouped lines above say it; the markdown (--markdown) keeps every row
        detail = detail[:40] + [f"  ... and {len(detail) - 40} more row(s) (--markdown FILE lists them all)"]
    lines += detail
    lines.append(verdict_line(c, allow_missing, fail_on_change))
    return "\n".join(lines)


def _count(n: int, noun: str) -> str:
    """``1 regression``, ``2 regressions``."""
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _md_escape(s: str) -> str:
    return str(s).replace("|", "\\|").replace("\n", " ").replace("<", "&lt;").replace(">", "&gt;")


def to_markdown(c: Comparison, baseline_dir, new_dir, allow_missing=False, new_variants=(),
                fail_on_change=False) -> str:
    """The comparison for a CI job summary: the verdict and, per changed variant, its category, cause and
    error ratios on the first screen; every row and record below, folded."""
    code = c.exit_code(allow_missing, fail_on_change)
    regressed = (any(v.category == "regression" for v in variant_changes(c))
                 or any(ch.engine == "(all)" for ch in c.of("regression")))
    head = ("✅ no regression" if code == 0
            else "❌ a new variant contradicts what it declares" if c.of("contradiction")
            else "❌ regression" if regressed
            else "❌ rows missing from the new results" if c.of("missing")
            else "❌ changed (--fail-on-change)")
    md = [f"## rbcheck compare: {head}", "",
          f"Baseline `{_md_escape(baseline_dir)}` vs new `{_md_escape(new_dir)}`: {c.matched_rows} "
          f"matching rows, **{_count(len(c.of('regression')), 'regression')}**, "
          f"{_count(len(c.of('improvement')), 'improvement')}, {len(c.of('new'))} new, "
          f"{len(c.of('missing'))} missing"
          + (f", **{_count(len(c.of('contradiction')), 'new verdict')} contradicting what the variant "
             "declares**"
             if c.of("contradiction") else "") + ".", ""]
    first = summary_lines(c, new_variants, allow_missing, fail_on_change)
    md += [f"**{_md_escape(first[0])}**", ""]
    vcs = variant_changes(c)
    if c.version_diffs:
        md += ["Versions changed: " + ", ".join(f"{_md_escape(p)} {_md_escape(a)} → {_md_escape(b)}"
                                               for p, a, b in c.version_diffs) + ".", ""]
    if vcs:
        md += ["| variant | change | cause | errors (new / old) |", "|---|---|---|---|"]
        md += [f"| {_md_escape(v.variant)} | {v.category} | "
               f"{_md_escape('; '.join(v.causes[:4]) or 'errors only').replace(' -&gt; ', ' → ')} | "
               f"{_md_escape(_ratio_text(v))} |" for v in vcs]
        md.append("")
    unchanged = _unchanged_variants(c, new_variants)
    if unchanged:
        md += [f"Unchanged: {len(unchanged)} variant(s) ({_md_escape(_names(unchanged, 12))}).", ""]
    if not_compared(c):
        md += [_md_escape(not_compared(c)[0].upper() + not_compared(c)[1:]) + ".", ""]
    if not_installed_sentence(c):   # one paragraph, however many engines
        md += [_md_escape(not_installed_sentence(c)) + ".", ""]
    if c.changes:
        md += ["<details><summary>Every changed row and record</summary>", ""]
    for kind, title in (("contradiction", "New verdicts that contradict the declaration"),
                        ("regression", "Regressions"), ("missing", "Missing rows"),
                        ("improvement", "Improvements"), ("new", "New rows"),
                        ("changed", "Other changes (not regressions)")):
        rows = c.of(kind)
        if not rows:
            continue
        md += [f"### {title}", "", "| scenario | engine | what | baseline | new | note |",
               "|---|---|---|---|---|---|"]
        md += [f"| {_md_escape(r.scenario)} | {_md_escape(r.engine)} | {_md_escape(r.what)} | "
               f"{_md_escape(r.old)} | {_md_escape(r.new)} | {_md_escape(r.note)} |" for r in rows]
        md.append("")
    if c.changes:
        md += ["</details>", ""]
    return "\n".join(md)
