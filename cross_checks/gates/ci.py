"""CI output in the formats CI systems read (docs/cli.md, "CI formats"): JUnit XML for ``sweep --junit FILE``
and ``compare --junit FILE``, the markdown a GitHub job summary shows (appended to ``$GITHUB_STEP_SUMMARY``),
and GitHub workflow commands (``--github-annotations``: ``::error title=…::…`` lines).

JUnit: one ``<testcase>`` per verdict — variant × scenario × quantity (classname ``rbcheck.VARIANT``, name
``SCENARIO: quantity``), the runs of a variant on a scenario (``SCENARIO: runs``), each long run, each
same-scheme agreement and each scenario's two references — with a ``<failure>`` for a contradiction, a failed
run or (compare) a regression, whose ``message`` is the verdict sentence the terminal prints; a verdict that
makes no claim (pre-asymptotic, too few points) is ``<skipped>``. Written with xml.etree.ElementTree.
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

from cross_checks.core.files import atomic_write_text
from cross_checks.gates.failures import failed_run_sentences, verdict_sentence

__all__ = ["sweep_junit", "compare_junit", "junit_text", "write_junit", "sweep_markdown",
           "append_step_summary", "annotation", "sweep_annotations", "compare_annotations",
           "STEP_SUMMARY_ENV"]

#: The environment variable GitHub Actions sets to the file a step appends its job summary to.
STEP_SUMMARY_ENV = "GITHUB_STEP_SUMMARY"
#: How much of a verdict's details a <failure> body holds (a CI page shows the message first).
_BODY_CHARS = 4000


class _Suites:
    """``<testsuites>`` built suite by suite, with the counts JUnit readers expect on every level."""

    def __init__(self, name: str):
        self.root = ET.Element("testsuites", name=name)
        self.suites: dict = {}

    def case(self, suite: str, classname: str, name: str, *, failure: str | None = None, kind: str = "",
             details: str = "", skipped: str | None = None) -> ET.Element:
        s = self.suites.get(suite)
        if s is None:
            s = self.suites[suite] = ET.SubElement(self.root, "testsuite", name=suite)
        tc = ET.SubElement(s, "testcase", classname=classname, name=name, time="0")
        if failure is not None:
            f = ET.SubElement(tc, "failure", message=failure, type=kind or "failure")
            f.text = (details or failure)[:_BODY_CHARS]
        elif skipped is not None:
            ET.SubElement(tc, "skipped", message=skipped)
        return tc

    def finish(self) -> ET.Element:
        totals = {"tests": 0, "failures": 0, "skipped": 0}
        for s in self.suites.values():
            cases = s.findall("testcase")
            n = {"tests": len(cases), "failures": sum(c.find("failure") is not None for c in cases),
                 "skipped": sum(c.find("skipped") is not None for c in cases)}
            for k, v in n.items():
                s.set(k, str(v))
                totals[k] += v
            s.set("errors", "0")
        for k, v in totals.items():
            self.root.set(k, str(v))
        self.root.set("errors", "0")
        return self.root


def _label(quantity: str) -> str:
    return quantity.replace("_", " ")


# --- sweep -----------------------------------------------------------------------------------------------

def sweep_junit(summary: dict, rows=(), long_rows=()) -> ET.Element:
    """The JUnit ``<testsuites>`` of a sweep: ``summary`` (summary.json), ``rows`` (results.csv as dicts:
    the failed runs' words), ``long_rows`` (long_runs.csv as dicts)."""
    x = _Suites("rbcheck sweep")
    failed = {}
    for _, variant, sentence, hit in failed_run_sentences(list(rows) + list(long_rows),
                                                               statuses=("failed",)):
        for r in hit:
            failed.setdefault((variant, r["scenario"]), []).append(sentence)
    pairs = {}
    for rec in summary.get("convergence", []):
        v, sc = rec["engine"], rec["scenario"]
        pairs.setdefault((v, sc), None)
        name = f"{sc}: {_label(rec['quantity'])}"
        if rec.get("matches_expectation") is False:
            x.case(v, f"rbcheck.{v}", name, failure=verdict_sentence(rec), kind="contradiction")
        elif rec.get("matches_expectation") is None:
            x.case(v, f"rbcheck.{v}", name, skipped=f"{v} on {sc}: {_label(rec['quantity'])} "
                                                    f"{rec.get('assessment', rec.get('verdict', ''))}")
        else:
            x.case(v, f"rbcheck.{v}", name)
    long_pairs = {(r["engine"], r["scenario"]) for r in summary.get("long_runs") or []}
    pairs.update(dict.fromkeys(k for k in failed if k not in long_pairs))   # failed with no record
    for (v, sc) in pairs:   # the runs of each (variant, scenario): failed runs, in the command's words
        words = list(dict.fromkeys(failed.get((v, sc), [])))
        x.case(v, f"rbcheck.{v}", f"{sc}: runs", failure=words[0] if words else None, kind="failed run",
               details="\n".join(words))
    for r in summary.get("long_runs") or []:
        v, sc = r["engine"], r["scenario"]
        sentence = f"{v} on {sc} (long run): {r.get('assessment', r.get('verdict', ''))}"
        words = list(dict.fromkeys(failed.get((v, sc), [])))
        if r.get("status") == "failed":
            x.case(v, f"rbcheck.{v}", f"{sc}: long run", failure=words[0] if words else sentence,
                   kind="failed run", details="\n".join(words) or sentence)
        elif r.get("matches_expectation") is False:
            x.case(v, f"rbcheck.{v}", f"{sc}: long run", failure=sentence, kind="contradiction")
        elif r.get("matches_expectation") is None:
            x.case(v, f"rbcheck.{v}", f"{sc}: long run", skipped=sentence)
        else:
            x.case(v, f"rbcheck.{v}", f"{sc}: long run")
    for r in summary.get("invariance") or []:   # the checks that do not hold (docs/invariance.md)
        name = f"{r['scenario']}: invariance under {r['transform']} {r['magnitude']}"
        if r["verdict"] == "broken":
            x.case(r["engine"], f"rbcheck.{r['engine']}", name,
                   failure=f"{r['engine']} on {r['scenario']}: invariance under {r['transform']} "
                           f"{r['magnitude']} {r['assessment']}", kind="contradiction")
        elif r["verdict"] == "known finding":   # declared beside its reason: said, not failed
            x.case(r["engine"], f"rbcheck.{r['engine']}", name, skipped=r["assessment"])
    for a in summary.get("agreement", []):
        sentence = (f"{a['a']} and {a['b']} differ on {a['scenario']} (should be the same scheme)"
                    if not a.get("agrees") else "")
        x.case("same-scheme agreement", "rbcheck.agreement", f"{a['a']} = {a['b']} on {a['scenario']}",
               failure=sentence or None, kind="contradiction")
    for sc in summary.get("scenarios", []):
        sr = sc.get("second_reference") or {}
        if sr.get("agrees") is None:
            continue
        sentence = (f"the references of {sc['name']} disagree: {sc['reference']} and {sr.get('label')} "
                    f"differ in {', '.join(sr.get('disagreeing', []))} beyond their measured accuracies")
        x.case("references", "rbcheck.references", f"{sc['name']}: {sc['reference']} = {sr.get('label')}",
               failure=None if sr["agrees"] else sentence, kind="contradiction")
    return x.finish()


# --- compare ---------------------------------------------------------------------------------------------

_METRIC_QUANTITY = {"pos": "position", "vel": "velocity", "orient": "orientation",
                    "angvel": "angular_velocity"}


def _change_case(ch) -> str:
    """The testcase a compare change belongs to: the quantity it is about, else the scenario's rows."""
    if ch.area in ("order", "local order", "contradiction") and " of " in ch.what:
        return f"{ch.scenario}: {_label(ch.what.rsplit(' of ', 1)[1])}"
    if ch.area == "row":
        metric = ch.what.split(" ")[-1]
        q = _METRIC_QUANTITY.get(metric.split("_err_")[0]) if "_err_" in metric else None
        if q:
            return f"{ch.scenario}: {_label(q)}"
    if ch.area == "agreement":
        return f"{ch.scenario}: {ch.what}"
    return f"{ch.scenario}: runs"


def _change_sentence(ch, category: str) -> str:
    if ch.kind == "contradiction":   # new: nothing to compare with; its own verdict sentence
        qty = _label(ch.what.rsplit(" of ", 1)[-1])
        return f"CONTRADICTION {ch.engine} on {ch.scenario}: {qty} {ch.note} (new in these results)"
    what = f"{ch.what}: {ch.old} -> {ch.new}".replace(": ->", ":").rstrip(" ->")
    head = {"contradiction": "CONTRADICTION", "missing": "MISSING"}.get(ch.kind, category.upper())
    return " ".join(f"{head} {ch.engine} on {ch.scenario}: {what} {ch.note}".split())


def compare_junit(c, new_summary: dict, allow_missing: bool = False,
                  fail_on_change: bool = False) -> ET.Element:
    """The JUnit ``<testsuites>`` of a comparison ``c`` (cross_checks.gates.compare.Comparison): a testcase
    per convergence record of the new results (and per changed row or record without one), failing where the
    exit code fails: a contradiction of a new variant, a regression of a variant judged as a whole to have
    regressed, rows missing (unless ``allow_missing``), any change with ``fail_on_change``."""
    from cross_checks.gates.compare import variant_changes
    category = {v.variant: v for v in variant_changes(c)}
    cases: dict = {}
    for rec in new_summary.get("convergence", []):
        cases.setdefault((rec["engine"], f"{rec['scenario']}: {_label(rec['quantity'])}"), [])
    for ch in c.changes:
        cases.setdefault((ch.engine, _change_case(ch)), []).append(ch)
    x = _Suites("rbcheck compare")

    def fails(ch) -> bool:
        cat = category.get(ch.engine)
        if fail_on_change:
            return True
        if ch.kind == "contradiction":
            return True
        if ch.kind == "missing":
            return not allow_missing
        return ch.kind == "regression" and (ch.engine == "(all)" or (cat is not None
                                                                       and cat.category == "regression"))
    for (variant, name), chs in sorted(cases.items()):
        bad = [ch for ch in chs if fails(ch)]
        cat = category.get(variant)
        sentences = [_change_sentence(ch, cat.category if cat else ch.kind) for ch in bad]
        if bad and cat is not None and cat.causes and bad[0].kind != "contradiction":
            sentences[0] += f" (the variant as a whole: {cat.category}; {'; '.join(cat.causes[:2])})"
        tc = x.case(variant, f"rbcheck.{variant}", name, failure=sentences[0] if sentences else None,
                    kind=bad[0].kind if bad else "", details="\n".join(sentences))
        others = [ch for ch in chs if not fails(ch)]
        if others:   # what changed without failing (an improvement, a changed scheme): said, not failed
            ET.SubElement(tc, "system-out").text = "\n".join(
                _change_sentence(ch, cat.category if cat else ch.kind) for ch in others)[:_BODY_CHARS]
    for pkg, a, b in c.version_diffs:
        x.case("versions", "rbcheck.versions", f"{pkg} {a} -> {b}",
               failure=f"version of {pkg} changed: {a} -> {b} (--fail-on-change)" if fail_on_change else None,
               kind="changed")
    return x.finish()


# --- files -----------------------------------------------------------------------------------------------

def junit_text(root: ET.Element) -> str:
    """The XML document of ``root`` (indented, with its declaration)."""
    tree = ET.ElementTree(root)
    ET.indent(tree)
    return ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"


def write_junit(path, root: ET.Element) -> None:
    """Write the JUnit file atomically (a reader never sees half of it)."""
    atomic_write_text(path, junit_text(root))


def append_step_summary(markdown: str, environ=None) -> str | None:
    """Append ``markdown`` to the file ``$GITHUB_STEP_SUMMARY`` names, when it is set; returns the path
    written ("" when unset). OSError when the file cannot be appended to (the caller says so and goes on)."""
    environ = os.environ if environ is None else environ
    path = environ.get(STEP_SUMMARY_ENV, "")
    if not path:
        return ""
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(markdown.rstrip("\n") + "\n\n")
    return path


# --- markdown of a sweep ------------------------------------------------------------------------------

def _md(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ").replace("<", "&lt;").replace(">", "&gt;")


def sweep_markdown(summary: dict, out_dir, rows=(), long_rows=()) -> str:
    """A sweep for a CI job summary: the verdict and its counts first, then every contradiction and every
    distinct reason of the failed runs (folded when long)."""
    from cross_checks.sweep.assemble import verdict_count
    total, wrong = verdict_count(summary)
    run = summary.get("run", {})
    lr = run.get("long_runs") or {}
    failed = failed_run_sentences(list(rows) + list(long_rows), statuses=("failed",))
    n_failed = run.get("failed_runs", 0) + lr.get("failed_runs", 0)
    ok = not wrong and not n_failed
    head = ("✅ all verdicts as expected" if ok
            else "❌ verdicts not as expected" if wrong else "❌ runs failed")
    runs = f"{run.get('runs', 0)} runs" + (f" and {lr.get('runs', 0)} long runs" if lr else "")
    md = [f"## rbcheck sweep: {head}", "",
          f"{len(summary.get('scenarios', []))} scenario(s) × {len(summary.get('variants', []))} variant(s), "
          f"{runs}: **{wrong} of {total} verdicts not as expected**, {n_failed} failed run(s), "
          f"{run.get('diverged_runs', 0) + lr.get('diverged_runs', 0)} diverged run(s). "
          f"Report: `{_md(Path(out_dir) / 'index.html')}`.", ""]
    contra = [verdict_sentence(r)
              for r in summary.get("convergence", []) if r.get("matches_expectation") is False]
    contra += [f"{r['engine']} on {r['scenario']} (long run): {r.get('assessment', '')}"
               for r in summary.get("long_runs") or [] if r.get("matches_expectation") is False]
    contra += [f"{a['a']} and {a['b']} differ on {a['scenario']} (should be the same scheme)"
               for a in summary.get("agreement", []) if not a.get("agrees")]
    from cross_checks.sweep.invariance import broken_lines
    broken = broken_lines(summary)
    contra += broken
    if broken:
        md[2] += f" **{len(broken)} broken invariance(s)** (invariance.csv)."
        if ok:
            md[0] = "## rbcheck sweep: ❌ invariance broken"
    inv = run.get("invariance") or {}
    if inv.get("known finding") or inv.get("no longer broken"):   # declared: said, not failed
        md[2] += (f" {inv.get('known finding', 0)} known invariance finding(s) (declared by their variants, "
                  f"with the reason), {inv.get('no longer broken', 0)} declared one(s) no longer broken.")
    if contra:
        fold = len(contra) > 10
        md += (["<details><summary>Not as expected</summary>", ""] if fold else ["**Not as expected**", ""])
        md += [f"- {_md(s)}" for s in contra] + [""] + (["</details>", ""] if fold else [])
    if failed:
        md += ["**Failed runs** (each distinct reason once, in the command's words)", ""]
        md += [f"- {_md(s)}" for _, _, s, _ in failed] + [""]
    return "\n".join(md)


# --- GitHub annotations -------------------------------------------------------------------------------------

def _escape_data(text: str) -> str:
    return str(text).replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")


def _escape_property(text: str) -> str:
    return _escape_data(text).replace(":", "%3A").replace(",", "%2C")


def annotation(level: str, title: str, message: str) -> str:
    """A GitHub workflow command: ``::error title=TITLE::MESSAGE`` (``level`` error, warning or notice),
    escaped as GitHub's toolkit escapes it."""
    return f"::{level} title={_escape_property(title)}::{_escape_data(message)}"


def sweep_annotations(summary: dict, rows=(), long_rows=()) -> list:
    """One ``::error`` per contradiction and per distinct failure reason; ``::warning`` for variants skipped
    and pairs an engine cannot express."""
    root = sweep_junit(summary, rows, long_rows)
    seen = dict.fromkeys(f.get("message") for f in root.iter("failure"))
    out = [annotation("error", "rbcheck sweep", m) for m in seen]
    out += [annotation("warning", "rbcheck sweep", f"skipped {v['name']}: {v['reason']}")
            for v in summary.get("skipped_variants") or []]
    out += [annotation("warning", "rbcheck sweep",
                       f"{r['engine']} cannot express {r['scenario']}: {r['reason']}")
            for r in summary.get("not_expressible") or []]
    return out


def compare_annotations(c, new_summary: dict, allow_missing=False, fail_on_change=False) -> list:
    """``::error`` per failing testcase of :func:`compare_junit` (its verdict sentence); ``::warning`` for a
    stale baseline and for optional engines not installed."""
    from cross_checks.gates.compare import not_installed_lines, variant_changes
    root = compare_junit(c, new_summary, allow_missing, fail_on_change)
    out = [annotation("error", "rbcheck compare", m)
           for m in dict.fromkeys(f.get("message") for f in root.iter("failure"))]
    if not fail_on_change:
        out += [annotation("warning", "rbcheck compare",
                           f"{v.variant}: {v.category} (the baseline is stale): " + "; ".join(v.causes[:2]))
                for v in variant_changes(c) if v.category in ("improvement", "scheme changed")]
    out += [annotation("warning", "rbcheck compare", line) for line in not_installed_lines(c)]
    return out
