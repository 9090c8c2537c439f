"""``rbcheck compare BASELINE_DIR NEW_DIR``: direction-aware regression check of two results directories.

Rows of ``results.csv`` are matched by (scenario, engine, dt). Each metric has a direction and an
absolute + relative tolerance (``METRIC_RULES``): errors and drifts are better when lower; a value
is a regression when ``new > old + abs_tol + rel_tol·|old|``, an improvement when
``new < old − abs_tol − rel_tol·|old|``. A status change away from ``ok`` is a regression.
Convergence records of ``summary.json`` are matched by (scenario, engine, quantity): an order that
moves further from its expected value by more than ``ORDER_TOL`` or a verdict that changes from
``converges`` is a regression. Engine versions of both provenances are compared and reported.

Either directory may be a full results directory (``rbcheck sweep``) or a compact baseline
(``rbcheck baseline``, :mod:`cross_checks.gates.baseline`): compare reads only what both hold. Both are
validated in full before anything is compared (the columns compare reads, a number in every numeric
cell, no negative error or drift, known statuses, no duplicate rows, a summary.json of a known schema
version with well-formed convergence records): damaged input is exit 2 with one line, never read as
"no regression". A metric column the baseline has and the new results lack, or an order that
vanished, is a regression.

A sweep of a subset (its summary.json lists the scenarios and variants it ran) is compared on what it
ran: baseline rows and records of a scenario or variant it did not run are counted as NOT COMPARED and
named in one line, not reported row by row as missing. A variant the new sweep left out because it was
unavailable there (its ``skipped_variants``) is still missing: its rows are what the gate must see.
Rows of a scenario and variant the new sweep ran are compared one by one; one absent there is missing.

Exit codes: 0 no regression; 1 regression (or missing rows, unless allowed); 2 unusable input.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from cross_checks.core.tolerances import COMPARE_ABS_TOL, COMPARE_REL_TOL, ORDER_TOL
from cross_checks.sweep.schema import STATUSES

__all__ = ["compare_dirs", "read_results_dir", "Comparison", "CompareInputError", "METRIC_RULES", "ORDER_TOL",
           "REQUIRED_COLUMNS", "Scope", "not_compared", "not_installed_lines", "verdict_line", "to_markdown", "to_text"]

KEY = ["scenario", "engine", "dt"]

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
    kind: str          # regression | improvement | new | missing | changed (informational)
    scenario: str
    engine: str
    what: str          # dt=... metric, or quantity
    old: str = ""
    new: str = ""
    note: str = ""


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

    def exit_code(self, allow_missing: bool = False) -> int:
        if self.of("regression") or (self.of("missing") and not allow_missing):
            return 1
        return 0


#: The columns every results.csv compare reads must have: those of docs/results.md that both a results
#: directory and a compact baseline (no timing columns) hold and compare reads or validates.
REQUIRED_COLUMNS = ("scenario", "engine", "dt", "steps", "pos_err_final", "vel_err_final", "orient_err_final",
                    "angvel_err_final", "energy_drift_max", "angmom_drift_max", "status")


def _number(csv, line, col, text, *, nonneg=False, positive=False):
    """A results.csv cell as a float (empty = NaN); CompareInputError naming line, column and reason."""
    t = text.strip()
    if t == "":
        if positive:
            raise CompareInputError(f"{csv}: line {line}: {col}: missing")
        return math.nan
    try:
        v = float(t)
    except ValueError:
        raise CompareInputError(f"{csv}: line {line}: {col}: not a number: {t[:40]!r}") from None
    if math.isnan(v):
        return v
    if not math.isfinite(v) or (nonneg and v < 0) or (positive and v <= 0):
        need = "a positive finite number" if positive else "a finite number >= 0 (or empty)" if nonneg else "finite"
        raise CompareInputError(f"{csv}: line {line}: {col}: must be {need}, got {t[:40]}")
    return v


def _read_csv(csv: Path) -> pd.DataFrame:
    try:
        raw = pd.read_csv(csv, dtype=str, keep_default_na=False, na_filter=False)
    except Exception as exc:  # noqa: BLE001 - pandas raises many kinds; all mean "unusable"
        raise CompareInputError(f"{csv}: cannot parse: {' '.join(str(exc).split()) or type(exc).__name__}") from None
    missing = [c for c in REQUIRED_COLUMNS if c not in raw.columns]
    if missing:
        raise CompareInputError(f"{csv}: columns {', '.join(missing)} missing")
    metrics = [m for m in METRIC_RULES if m in raw.columns]
    out = {c: [] for c in ["scenario", "engine", "dt", "status", *metrics]}
    for i, r in enumerate(raw.itertuples(index=False), start=2):
        r = r._asdict() if hasattr(r, "_asdict") else dict(zip(raw.columns, r))
        for c in ("scenario", "engine"):
            if not r[c].strip():
                raise CompareInputError(f"{csv}: line {i}: {c}: empty")
            out[c].append(r[c])
        if r["status"] not in STATUSES:
            raise CompareInputError(f"{csv}: line {i}: status: must be one of {', '.join(STATUSES)}, "
                                    f"got {r['status'][:40]!r}")
        out["status"].append(r["status"])
        out["dt"].append(_number(csv, i, "dt", r["dt"], positive=True))
        _number(csv, i, "steps", r["steps"], nonneg=True)
        for m in metrics:
            out[m].append(_number(csv, i, m, r[m], nonneg=True))
    df = pd.DataFrame(out)
    if df.duplicated(KEY).any():
        dup = df[df.duplicated(KEY)].iloc[0]
        raise CompareInputError(f"{csv}: duplicate row for {dup['scenario']}, {dup['engine']}, dt={dup['dt']}")
    return df


def _read_summary(sj: Path) -> dict:
    from cross_checks.sweep.schema import SchemaError, check_summary
    if not sj.is_file():
        raise CompareInputError(f"{sj}: missing (every results directory written by `rbcheck sweep` has one)")
    try:
        summary = json.loads(sj.read_text(encoding="utf-8"))
    except (ValueError, RecursionError) as exc:
        raise CompareInputError(f"{sj}: cannot parse JSON: {str(exc) or type(exc).__name__}") from None
    try:
        check_summary(summary)
    except SchemaError as exc:
        raise CompareInputError(f"{sj}: {exc}") from None
    return summary


def read_results_dir(d: Path):
    """``(results.csv as a DataFrame of the columns compare reads, summary.json)`` of a results directory
    or a compact baseline, validated in full (CompareInputError naming the file, the field and the reason)."""
    d = Path(d)
    if not d.is_dir():
        raise CompareInputError(f"{d}: not a directory")
    csv = d / "results.csv"
    if not csv.is_file():
        raise CompareInputError(f"{csv}: missing (is {d} a results directory written by `rbcheck sweep`?)")
    try:
        return _read_csv(csv), _read_summary(d / "summary.json")
    except (OSError, UnicodeDecodeError) as exc:
        raise CompareInputError(f"{d}: cannot read: {exc}") from None


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
        return expected_order(rec["engine"], rec["quantity"], rec.get("scenario"))
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
    _compare_versions(old_sum.get("provenance", {}), new_sum.get("provenance", {}), out)
    return out


def _scope(summary: dict, required: frozenset = frozenset()) -> Scope:
    """What a results directory's sweep ran, from its summary.json (everything when it does not say)."""
    skipped = summary.get("skipped_variants") or []
    optional_absent = {v["name"]: v["reason"] for v in skipped
                       if v.get("installed") is False and v.get("required") is False}
    broken = {v["name"]: v["reason"] for v in skipped if v["name"] not in optional_absent}
    if not isinstance(summary.get("scenarios"), list) or not isinstance(summary.get("variants"), list):
        return Scope(unavailable=broken, not_installed=optional_absent, required=required)
    return Scope(frozenset(s["name"] for s in summary["scenarios"]), frozenset(v["name"] for v in summary["variants"]),
                 broken, optional_absent, required)


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
            out.changes.append(Change("new", "(all)", "(all)", f"column {metric}", note="metric new in these results"))


def _compare_rows(merged, out: Comparison):
    """Rows matched by (scenario, engine, dt): missing, new, a status change, or each metric judged."""
    for _, r in merged.iterrows():
        where = f"dt={r['dt']:g}"
        if r["_merge"] == "left_only":
            if not out.scope.ran(r["scenario"], r["engine"]):
                out.scope.skip(r["scenario"], r["engine"])
                continue
            why = out.scope.unavailable.get(r["engine"]) or out.scope.not_installed.get(r["engine"])
            note = f"variant unavailable in the new sweep: {why}" if why else "row absent from the new results"
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
                    out.changes.append(Change(kind, r["scenario"], r["engine"], f"{where} {metric}", old, new, note))


def _metric_change(vo, vn, abs_tol, rel_tol):
    """``(kind, old, new, note)`` when a lower-is-better metric moved beyond its tolerance, else None."""
    if pd.isna(vo) and pd.isna(vn):
        return None
    if pd.isna(vo) or pd.isna(vn):
        return ("regression" if pd.isna(vn) else "improvement"), _fmt(vo), _fmt(vn), "value appeared/disappeared"
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


def _compare_convergence(old_recs, new_recs, out: Comparison):
    """Convergence records matched by (scenario, engine, quantity): missing, new, a verdict change, or
    the order judged (:func:`_order_change`)."""
    key = lambda rec: (rec["scenario"], rec["engine"], rec["quantity"])  # noqa: E731
    old = {key(r): r for r in old_recs}
    new = {key(r): r for r in new_recs}
    for k in sorted(set(old) | set(new)):
        scen, eng, qty = k
        if k not in new:
            if not out.scope.ran(scen, eng):
                out.scope.skip(scen, eng, record=True)
                continue
            out.changes.append(Change("missing", scen, eng, f"order of {qty}", note="convergence record absent"))
        elif k not in old:
            out.changes.append(Change("new", scen, eng, f"order of {qty}", new=_fmt(new[k].get("order"))))
        elif old[k].get("verdict") != new[k].get("verdict"):
            vo, vn = old[k].get("verdict"), new[k].get("verdict")
            out.changes.append(Change(_verdict_change_kind(vo, vn), scen, eng, f"verdict of {qty}", str(vo), str(vn)))
        else:
            change = _order_change(old[k], new[k])
            if change is not None:
                kind, old_order, new_order, note = change
                out.changes.append(Change(kind, scen, eng, f"order of {qty}", old_order, new_order, note))


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
    out = {k: str(val) for k, val in v.items() if k in ("rbcheck", "numpy", "scipy", "mujoco", "pybullet", "python")}
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
        if vo.get(k) != vn.get(k):
            out.version_diffs.append((k, vo.get(k, "—"), vn.get(k, "—")))


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
        out.append(f"{engine} not installed: {sc.absent_rows.get(engine, 0)} baseline rows and "
                   f"{sc.absent_records.get(engine, 0)} convergence records not compared (an optional engine; "
                   f"--require {engine} makes its absence a failure)")
    return out


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
    return (f"not compared: {sc.skipped_rows} baseline row(s) and {sc.skipped_records} convergence record(s) of "
            f"{' and '.join(what)} the new results did not run")


def verdict_line(c: Comparison, allow_missing=False) -> str:
    """What the exit code means, in words that agree with the counts."""
    n_reg, n_miss = len(c.of("regression")), len(c.of("missing"))
    if n_reg:
        return f"REGRESSION: {n_reg} regression(s)" + (f", {n_miss} missing" if n_miss else "")
    if n_miss and not allow_missing:
        return (f"MISSING: {n_miss} row(s) or record(s) of what the new results ran are absent from them "
                "(--allow-missing accepts that)")
    return "OK: no regression"


def to_text(c: Comparison, allow_missing=False) -> str:
    lines = [f"compared {c.matched_rows} matching rows: {len(c.of('regression'))} regressions, "
             f"{len(c.of('improvement'))} improvements, {len(c.of('new'))} new, {len(c.of('missing'))} missing"]
    if not_compared(c):
        lines.append(not_compared(c))
    lines += not_installed_lines(c)
    for pkg, a, b in c.version_diffs:
        lines.append(f"  version of {pkg}: {a} -> {b}")
    for kind in ("regression", "missing", "improvement", "new", "changed"):
        for ch in c.of(kind):
            lines.append(f"  {kind.upper():<11} {ch.scenario} {ch.engine} {ch.what}: {ch.old} -> {ch.new} {ch.note}".rstrip())
    lines.append(verdict_line(c, allow_missing))
    return "\n".join(lines)


def _md_escape(s: str) -> str:
    return str(s).replace("|", "\\|").replace("\n", " ").replace("<", "&lt;").replace(">", "&gt;")


def to_markdown(c: Comparison, baseline_dir, new_dir, allow_missing=False) -> str:
    code = c.exit_code(allow_missing)
    head = ("✅ no regression" if code == 0 else "❌ regression" if c.of("regression")
            else "❌ rows missing from the new results")
    md = [f"## rbcheck compare: {head}", "",
          f"Baseline `{_md_escape(baseline_dir)}` vs new `{_md_escape(new_dir)}`: {c.matched_rows} matching rows, "
          f"**{len(c.of('regression'))} regressions**, {len(c.of('improvement'))} improvements, "
          f"{len(c.of('new'))} new, {len(c.of('missing'))} missing.", ""]
    if not_compared(c):
        md += [_md_escape(not_compared(c)[0].upper() + not_compared(c)[1:]) + ".", ""]
    md += [_md_escape(line) + ".\n" for line in not_installed_lines(c)]
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
