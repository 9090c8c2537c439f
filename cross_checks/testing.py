"""Public testing API: check your own simulator's declared order of accuracy in your own pytest suite.

:func:`assert_engine` is stable: its signature and behaviour change only with a major version. It is
also offered as the ``assert_engine`` fixture of rbcheck's pytest plugin (entry point ``pytest11``,
:mod:`cross_checks.pytest_plugin`), which adds a per-session cache and ``--rbcheck-keep-reports DIR``.

A complete user test file (docs/engines.md)::

    from pathlib import Path
    ENGINE = Path(__file__).parent / "cbody.toml"

    def test_cbody_euler_is_first_order(assert_engine):
        assert_engine("cbody:euler", ["projectile", "tennis_racket"], engine_file=ENGINE)
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

__all__ = ["assert_engine"]


def assert_engine(variant, scenarios, *, engine_file=None, invariance: bool = False) -> dict:
    """Sweep ``variant`` over the Δt ladders of ``scenarios`` and assert that its verdicts agree with the
    order its engine declares, and that no run failed or diverged.

    Parameters
    ----------
    variant : str
        ``"ENGINE:VARIANT"`` (e.g. ``"mysim:euler"``), or an engine name for all its variants.
    scenarios : str, path, Scenario, or a list of them
        Catalog names (``rbcheck list``) or scenario TOML files; each needs a ``dt_ladder`` of at least
        two steps (the order is fitted over it).
    engine_file : str or path, or a list of them, optional
        Engine file(s) to register first (engine-file engines). Entry-point engines need none.
    invariance : bool, optional
        Also run the invariance checks (docs/invariance.md): each scenario translated, in a rotated world,
        with a non-principal body frame and scaled, mapped back and compared with the variant's own run of
        the original; a broken invariance is a problem (its sentence names the transform and the deviation).

    Returns
    -------
    dict
        The sweep's summary (as summary.json: provenance, variants, convergence records, ...).

    Raises
    ------
    AssertionError
        One line per problem, each a verdict sentence: a quantity whose errors do not shrink at the
        declared order (with the errors and steps), a failed run (with the engine's own words), a
        diverged run (with the time), an engine that is unavailable here, or a scenario the engine
        cannot express (EngineAdapter.expressible: nothing was checked there).
    ValueError
        Bad input: an unknown variant or scenario, a bad engine file (``FILE: FIELD: REASON``), a
        scenario without a Δt ladder.
    """
    __tracebackhide__ = True   # pytest shows the verdict, not rbcheck's own frames
    return run_engine_checks(variant, scenarios, engine_file=engine_file, invariance=invariance)


def run_engine_checks(variant, scenarios, *, engine_file=None,
                      out_dir=None, cache_dir=None, jobs=None, invariance: bool = False) -> dict:
    """:func:`assert_engine` with the plugin's settings: ``out_dir`` keeps the results directory and its
    HTML report there; ``cache_dir`` replaces the user's rbcheck cache; ``jobs`` worker processes."""
    __tracebackhide__ = True
    from cross_checks.engines import EngineUnavailable, engine_files_registered, get_adapter
    from cross_checks.sweep import SweepError, run_sweep
    from cross_checks.sweep.cache import using_cache_dir

    if out_dir is not None:
        from reports.install import check_templates
        check_templates()  # the kept report's templates, before the runs
    with contextlib.ExitStack() as stack:
        stack.enter_context(engine_files_registered(as_list(engine_file)))
        variants = _variants(variant)
        for engine in dict.fromkeys(v.split(":", 1)[0] for v in variants):
            try:
                get_adapter(engine)
            except EngineUnavailable as exc:
                raise AssertionError(
                    f"assert_engine({variant!r}): the engine is unavailable here: {exc}") from None
        scs = _scenarios(scenarios)
        if out_dir is None:
            out = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="rbcheck-assert-"))) / "results"
        else:
            out = Path(out_dir)
        if cache_dir is not None:
            stack.enter_context(using_cache_dir(cache_dir))
        try:
            summary = run_sweep(scs, variants, out, jobs=jobs, progress=False,
                                finish=_render if out_dir is not None else None,
                                **({"invariance": True} if invariance else {}))
        except SweepError as exc:
            raise ValueError(str(exc)) from None
        rows = _read_rows(out / "results.csv")
        problems = verdict_problems(summary, rows)
        if invariance:
            from cross_checks.sweep.invariance import broken_lines
            problems += broken_lines(summary)
        failed = {(r["scenario"], r["engine"]) for r in rows if r["status"] in ("failed", "diverged")}
        wrong = dict.fromkeys((r["scenario"], r["engine"]) for r in summary.get("convergence", [])
                              if r.get("matches_expectation") is False
                              and (r["scenario"], r["engine"]) not in failed)
        # its engines still registered
        causes = likely_causes({s.name: s for s in scs}, wrong) if problems else {}
    if problems:
        lines = [f"  {p}" for p in problems]
        lines += [f"  likely cause ({v} on {sc}): {c}" for (sc, v), c in causes.items()]
        where = f"\n  results and report kept in {out}" if out_dir is not None else ""
        raise AssertionError(f"assert_engine({variant!r}) on {', '.join(s.name for s in scs)}: "
                             f"{len(problems)} problem(s):\n" + "\n".join(lines) + where)
    return summary


def verdict_problems(summary: dict, rows: list) -> list:
    """The sentences :func:`assert_engine` raises with, one per DISTINCT failure: runs that failed with the
    same words are one sentence naming every run they hit; then diverged runs; then every convergence verdict
    that contradicts its expectation (the declared order) — except of a (scenario, variant) whose runs failed
    (the failure is the cause, said once)."""
    from cross_checks.gates.failures import failed_run_sentences, verdict_sentence
    groups = failed_run_sentences(rows)
    out = [sentence for _, _, sentence, _ in groups]
    failed_pairs = {(r["scenario"], r["engine"]) for *_, hit in groups for r in hit}
    for rec in summary.get("convergence", []):
        if rec.get("matches_expectation") is False and (rec["scenario"], rec["engine"]) not in failed_pairs:
            out.append(verdict_sentence(rec))
    # a pair the engine cannot express was not run: nothing about it was checked, so it cannot pass (a sweep
    # over many engines lists these pairs and goes on; an assertion about one engine may not)
    for r in summary.get("not_expressible") or []:
        out.append(f"{r['engine']} cannot express {r['scenario']}, so nothing was checked there: "
                   f"{r['reason']} (leave the scenario out of this assertion)")
    return out


def likely_causes(scenarios: dict, problems_of) -> dict:
    """:func:`cross_checks.gates.failures.likely_causes` (kept here: part of this module's API)."""
    from cross_checks.gates.failures import likely_causes as causes
    return causes(scenarios, problems_of)


def as_list(x) -> list:
    if x is None:
        return []
    if isinstance(x, (str, os.PathLike)):
        return [x]
    return list(x)


def _variants(variant) -> list:
    from cross_checks.engines import UnknownVariant, engine_variants, resolve
    if not isinstance(variant, str) or not variant:
        raise ValueError(f"variant must be 'ENGINE:VARIANT' or an engine name, got {variant!r}")
    try:
        names = ([variant] if ":" in variant else [f"{variant}:{v}" for v in engine_variants(variant)])
        names = [resolve(n, strict=True) for n in names]
    except UnknownVariant as exc:
        raise ValueError(str(exc)) from None
    if not names:
        raise ValueError(f"engine {variant!r} cannot be loaded (see `rbcheck list`)")
    return names


def _scenarios(scenarios) -> list:
    from cross_checks.scenario import Scenario, load_scenario
    items = [scenarios] if isinstance(scenarios, (str, os.PathLike, Scenario)) else list(scenarios)
    if not items:
        raise ValueError("scenarios: give at least one scenario (catalog name or TOML path)")
    out = [s if isinstance(s, Scenario) else load_scenario(s) for s in items]
    for s in out:
        if len(s.dt_ladder_s) < 2:
            raise ValueError(f"{s.source}: dt_ladder: needs at least two steps to fit an order, got "
                             f"{list(s.dt_ladder_s)}")
    return out


def _read_rows(path: Path) -> list:
    import csv
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _render(results_dir) -> None:
    """The HTML/PNG report of a kept results directory (``--rbcheck-keep-reports``)."""
    import reports
    reports.render(results_dir)
