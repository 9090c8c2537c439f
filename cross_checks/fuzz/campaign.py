"""``rbcheck fuzz``: batches of random cases until the budget is spent, then each distinct failure shrunk
to a minimal scenario file that ``rbcheck sweep`` confirms (docs/fuzz.md §3–§4).

* A campaign of seed S is the sequence of batches 0, 1, 2, …; batch b holds cases b·BATCH … (b+1)·BATCH − 1
  (each drawn from its own generator, :func:`~cross_checks.fuzz.generate.case_rng`) at n0 = N0_CYCLE[b mod 3]
  steps per coarsest rung: deterministic per seed, whatever worker runs a batch; the budget only decides
  how many batches it reaches.
* Batches run on the sweep's :class:`~cross_checks.sweep.execute.Runner` (here, its process pool, or any
  ``concurrent.futures.Executor``); a batch's outcome is cached (``sweep.cache``) under a key holding the
  seed, the batch, the variants, the engine versions, the numerical stack and rbcheck's source fingerprint.
* The first case of each distinct failure is shrunk (:mod:`~cross_checks.fuzz.shrink`, SHRINK_S seconds
  each, MAX_SHRUNK failures), confirmed with ``rbcheck sweep`` and written as
  ``DIR/counterexamples/<name>.toml``; ``DIR/fuzz.json`` is the summary. DIR is replaced as a whole.
"""
from __future__ import annotations

import json
import math
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from cross_checks.analysis.convergence import fmt_order
from cross_checks.core.files import atomic_write_text
from cross_checks.fuzz import generate, known, pipeline
from cross_checks.fuzz import properties as P
from cross_checks.fuzz import shrink as S

__all__ = ["BATCH", "N0_CYCLE", "SHRINK_S", "MAX_SHRUNK", "FuzzError", "run_batch", "run_campaign",
           "SUMMARY", "FORMAT"]

#: Cases per batch: the stacked exact solves and the batched engine runs (``simulate_many``) cost per call
#: nearly what they cost for one case, so 64 cases share a batch's fixed costs; few enough that a batch
#: stays short (a batch started is finished: the budget decides which start).
BATCH = 64
#: Steps at a batch's coarsest rung, cycled over the batches (short and long runs: a long run lets an
#: error grow, a short one reaches the coarsest fair step).
N0_CYCLE = (8, 16, 32)
#: Seconds of shrinking per distinct failure, and how many failures are shrunk (the rest are listed).
SHRINK_S = 60.0
MAX_SHRUNK = 6
SUMMARY = "fuzz.json"
FORMAT = "rbcheck fuzz summary"


class FuzzError(ValueError):
    """Bad input (one line)."""


def _clean(o):
    """JSON-ready: NumPy scalars and arrays as Python, non-finite numbers as None."""
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, np.ndarray):
        return _clean(o.tolist())
    if isinstance(o, (np.bool_, bool)):
        return bool(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(o) else None
    return o


# --- one batch ---------------------------------------------------------------------------------------

def _cache_key(seed, batch, variants) -> str:
    from cross_checks.engines import engine_provenance
    from cross_checks.sweep.fingerprint import code_fingerprint, environment
    engines = sorted({v.split(":", 1)[0] for v in variants})
    parts = {"fuzz": [int(seed), int(batch), BATCH, N0_CYCLE], "variants": list(variants),
             "engines": {e: [engine_provenance(e), code_fingerprint(e)] for e in engines},
             "reference": code_fingerprint("reference"), "env": environment()}
    return json.dumps(parts, sort_keys=True, default=str)


def _cache_path(cache_root, key):
    import hashlib
    return Path(cache_root) / "fuzz" / f"{hashlib.sha256(key.encode()).hexdigest()}.npz"


def compute_batch(seed, batch, variants) -> dict:
    """One batch of ``variants`` (Resolved: :func:`run_campaign` resolves them once; every property reads
    what they declare)."""
    n0 = N0_CYCLE[batch % len(N0_CYCLE)]
    draws = [generate.draw(seed, batch * BATCH + k) for k in range(BATCH)]
    from threadpoolctl import threadpool_limits

    # one BLAS thread: the large stacked DOP853 solves give the same last bits whatever the machine's core
    # count (a batch is a function of its seed alone, as the cache key assumes), and two workers on two
    # cores do not fight over BLAS threads (docs/fuzz.md §4)
    with threadpool_limits(limits=1, user_api="blas"):
        cases = pipeline.prepare(draws, n0)
        contexts, members, y_end = pipeline.measure(cases)
        outcomes, seconds = pipeline.evaluate(cases, contexts, members, y_end, variants)
    out = []
    for c, o in zip(cases, outcomes):
        out.append({"index": c.index, "numbers": o.numbers, "violations": o.violations, "tally": o.tally,
                    "not_expressible": o.not_expressible, "spec": c.spec if o.violations else None})
    return _clean({"seed": seed, "batch": batch, "n0": n0, "cases": out, "seconds": seconds})


def run_batch(item) -> dict:
    """``item`` = (seed, batch, variants, user_engines, cache_root, use_cache, marker): the batch's outcome
    as JSON-ready data (cached). Runs in a worker: one small pickle in, one out. ``marker`` (a file path,
    or None) exists while the batch runs, so after a worker crash the parent knows which batches were in
    flight."""
    seed, batch, variants, user_engines, cache_root, use_cache, marker = item
    if marker is not None:
        Path(marker).touch()
    try:
        return _batch_outcome(seed, batch, variants, user_engines, cache_root, use_cache)
    finally:
        if marker is not None:
            Path(marker).unlink(missing_ok=True)


def _batch_failed(seed, batch, why) -> dict:
    """The outcome of a batch rbcheck could not judge: no cases, the reason (summary: ``batch_errors``)."""
    return {"seed": seed, "batch": batch, "n0": N0_CYCLE[batch % len(N0_CYCLE)], "cases": [], "seconds": {},
            "cached": False, "error": why}


def _batch_outcome(seed, batch, variants, user_engines, cache_root, use_cache) -> dict:
    from cross_checks.engines import adopt_user_engines
    from cross_checks.sweep import cache
    adopt_user_engines(user_engines)
    key = path = None
    if cache_root is not None:
        key = _cache_key(seed, batch, variants)
        path = _cache_path(cache_root, key)
        if use_cache:
            hit = cache.load(Path(cache_root), path, key)
            if hit is not None:
                res = json.loads(str(hit["outcome"]))
                res["cached"] = True
                return res
    try:
        res = compute_batch(seed, batch, variants)
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:  # noqa: BLE001 - one batch rbcheck could not judge never stops the campaign
        return _batch_failed(seed, batch, f"{type(exc).__name__}: {exc}")
    if path is not None:
        cache.store(Path(cache_root), path, key, {"outcome": np.array(json.dumps(res))})
    res["cached"] = False
    return res


# --- the search ----------------------------------------------------------------------------------------

def search(seed, variants, budget_s, *, jobs=1, executor=None, cache_root=None, use_cache=True,
           on_batch=None) -> list:
    """Batches 0, 1, … until ``budget_s`` seconds have passed (a batch started is finished; batch 0 always
    runs): [batch result] in batch order. They run on the sweep's :class:`~cross_checks.sweep.execute.Runner`
    — here (``jobs`` 1), in its process pool (``jobs`` batches at a time; a batch whose worker dies is
    rerun alone and, dying again, is a result with an ``error`` saying so) or on ``executor`` (Dask).
    ``on_batch(result)`` is called as each finishes."""
    import tempfile

    from cross_checks.engines import user_engines
    from cross_checks.sweep.execute import Runner
    extra = user_engines()
    deadline = time.monotonic() + float(budget_s)
    if jobs > 1 and executor is None:
        from cross_checks.engines import packed_rows
        from reference_sim import compiled
        compiled.warm()   # the compiled reference steps, loaded once here: the forked workers inherit them
        packed_rows.warm()   # and MuJoCo's conversion of a record (engines.packed_rows)
    runner = Runner(max(1, int(jobs)), executor)
    results = []
    with tempfile.TemporaryDirectory(prefix="rbcheck-fuzz-") as inflight:
        def batches():
            b = 0
            while b == 0 or time.monotonic() < deadline:
                marker = None if executor is not None else str(Path(inflight) / str(b))
                yield (seed, b, list(variants), extra, cache_root, use_cache, marker)
                b += 1

        def done(_item, r):
            results.append(r)
            if on_batch:
                on_batch(r)

        def crashed(item):
            if item[-1] is not None:
                Path(item[-1]).unlink(missing_ok=True)
            return _batch_failed(seed, item[1], "the worker process died running this batch, alone (a crash "
                                                "inside an engine?)")
        try:
            runner.map_unordered(run_batch, batches(), done, on_crash=crashed,
                                 in_flight=lambda item: item[-1] is not None and Path(item[-1]).exists(),
                                 window=max(1, int(jobs)))
        except BaseException:
            runner.close(kill=True)
            raise
        runner.close()
    return sorted(results, key=lambda r: r["batch"])


# --- tallies -------------------------------------------------------------------------------------------

def _tallies(results, variants) -> dict:
    per = {v: {"cases": 0, "seconds": 0.0, "not_expressible": 0,
               "properties": {p: [0, 0] for p in P.PROPERTIES}} for v in variants}
    pairs = {}
    for r in results:
        judged = sum(1 for c in r["cases"] if "skipped" not in c["numbers"])
        for v, s in r["seconds"].items():
            if v in per:
                per[v]["seconds"] += float(s or 0.0)
                per[v]["cases"] += judged
        for c in r["cases"]:
            for v in c.get("not_expressible") or {}:
                if v in per:
                    per[v]["cases"] -= 1
                    per[v]["not_expressible"] += 1
            for v, t in c["tally"].items():
                into = (per[v]["properties"] if v in per
                        else pairs.setdefault(v, {p: [0, 0] for p in P.PROPERTIES}))
                for p, (a, n) in t.items():
                    into[p][0] += a
                    into[p][1] += n
    for d in per.values():
        d["cases_per_s"] = d["cases"] / d["seconds"] if d["seconds"] > 0 else None
    return {"per_variant": per, "pairs": pairs}


_RANGED = ("hL", "chi", "amplification", "A_chi", "anisotropy", "separatrix_proximity", "stiffness_dt2_per_m")


def _numbers_seen(results) -> dict:
    out = {}
    for k in _RANGED:
        vals = [c["numbers"].get(k) for r in results for c in r["cases"] if "skipped" not in c["numbers"]]
        vals = [v for v in vals if v is not None]
        if vals:
            out[k] = {"min": min(vals), "median": float(np.median(vals)), "max": max(vals)}
    kinds = {}
    for r in results:
        for c in r["cases"]:
            n = c["numbers"]
            for key in ("body", "shape", "spin"):
                if key in n:
                    kinds.setdefault(key, {}).setdefault(n[key], 0)
                    kinds[key][n[key]] += 1
            for f in n.get("forces", []) or []:
                kinds.setdefault("forces", {}).setdefault(f, 0)
                kinds["forces"][f] += 1
    out["kinds"] = kinds
    return out


# --- counterexamples ---------------------------------------------------------------------------------

#: Properties that ``rbcheck sweep``'s gates check (a free-running order, a same-scheme pair): a failure
#: of one of these is shrunk first, so that the counterexample reproduces with the sweep's exit 1.
_SWEEP_GATED = ("agreement", "free_running_order")


def _failures(results) -> dict:
    """{(variants, explained): {"variants", "explained", "hits": [(seed, index, violation, spec)],
    "also": {property: cases}}}: one distinct failure per variant set (per pair for agreement) and per
    whether a documented engine behaviour (``known.explain``, judged on each case as drawn) accounts for
    it, in campaign order — so an unexplained failure of a variant is never listed under the explained
    counterexample of the same variant. ``hits`` are the violations of the property to shrink — the
    first sweep-gated property that failed, else the first that failed."""
    by: dict = {}
    for r in results:
        for c in r["cases"]:
            if not c["violations"]:
                continue
            scenario = pipeline.scenario_of(c["spec"])
            for v in c["violations"]:
                key = (tuple(v["variants"]), bool(known.explain(scenario, v)))
                by.setdefault(key, []).append((r["seed"], c["index"], v, c["spec"]))
    out = {}
    for key, hits in by.items():
        gated = [h for h in hits if h[2]["property"] in _SWEEP_GATED]
        prop = (gated or hits)[0][2]["property"]
        chosen = [h for h in hits if h[2]["property"] == prop]
        also: dict = {}
        for h in hits:
            if h[2]["property"] != prop:
                also.setdefault(h[2]["property"], set()).add(h[1])
        out[key] = {"variants": key[0], "explained": key[1], "hits": chosen,
                    "cases": len({(h[0], h[1]) for h in chosen}),
                    "also": {p: len(i) for p, i in also.items()}}
    return out


def _same_finding(sig, explained: bool):
    """``keep(spec, outcome)`` for the shrinker: the case still shows ``sig`` with a violation that a
    documented engine behaviour explains (``explained``) or does not — shrinking must not wander from an
    unexplained failure into an explained one of the same variant (or back)."""
    def keep(spec, outcome) -> bool:
        scenario = pipeline.scenario_of(spec)
        return any(S.signature(v) == sig and bool(known.explain(scenario, v)) == explained
                   for v in outcome.violations)
    return keep


def _magnitude(v) -> str:
    if v.get("ratio") is not None:
        return f"{v['ratio']:.3g}× its allowance"
    if v.get("order_deficit") is not None:
        return f"order {fmt_order(v['order'])} where {v['expected_order']:g} is expected"
    return v.get("verdict") or v["property"]


def _reproduce_line(file_name, variants, engine_files) -> str:
    ef = "".join(f" --engine-file {f}" for f in engine_files)
    return f"rbcheck sweep {file_name} --engines {' '.join(variants)}{ef} --jobs 1 --out DIR"


def _counterexample(failure, engine_files, deadline, log) -> dict:
    """Shrink the first case of a failure, confirm it with rbcheck sweep: the counterexample record."""
    hits = failure["hits"]
    seed, index, violation, spec = hits[0]
    sig = S.signature(violation)
    variants = list(sig[1])
    t0 = time.monotonic()
    small, steps = S.shrink(spec, sig, variants, deadline=min(deadline, t0 + SHRINK_S),
                            keep=_same_finding(sig, failure["explained"]))
    chain = [small] if small is spec else [small, spec]
    confirmed, gate, final = False, [], small
    for cand in chain:
        gate = S.confirm(cand, variants)
        if gate:
            confirmed, final = True, cand
            break
    outcome = pipeline.evaluate_specs([final], variants)[0]
    final_scenario = pipeline.scenario_of(final)
    found = [v for v in (outcome.violations if outcome else []) if S.signature(v) == sig
             and bool(known.explain(final_scenario, v)) == failure["explained"]]
    v_final = found[0] if found else violation
    why = known.explain(final_scenario, v_final)
    log(f"  {sig[0]} of {' / '.join(variants)}: case {index}, shrunk in {len(steps)} "
        f"step(s) ({time.monotonic() - t0:.0f} s), "
        f"{'confirmed by rbcheck sweep' if confirmed else 'NOT confirmed by rbcheck sweep'}")
    return {"property": sig[0], "variants": variants, "quantity": sig[2], "outcome": sig[3], "seed": seed,
            "index": index, "cases_with_this_failure": failure["cases"], "sentence": v_final["sentence"],
            "magnitude": _magnitude(v_final), "first_sentence": violation["sentence"], "shrink_steps": steps,
            "spec": final, "confirmed_by_sweep": confirmed, "sweep_failures": gate, "explanation": why,
            "engine_files": list(engine_files), "also_failed": failure["also"],
            "sweep_gated": sig[0] in _SWEEP_GATED}


def _file_text(cx, file_name) -> str:
    lines = [f"rbcheck fuzz counterexample (seed {cx['seed']}, case {cx['index']}; "
             f"{cx['cases_with_this_failure']} case(s) of the campaign failed the same way)",
             f"property: {cx['property']} — {cx['magnitude']}", cx["sentence"]]
    if cx["explanation"]:
        lines.append(f"explained by the engine's documented behaviour: {cx['explanation']}")
    if cx["shrink_steps"]:
        lines.append("shrunk: " + "; ".join(cx["shrink_steps"]))
    lines.append(("reproduce (exit 1): " if cx["confirmed_by_sweep"] else "run: ")
                 + _reproduce_line(file_name, cx["variants"], cx["engine_files"]))
    if cx["also_failed"]:
        lines.append("the same variant(s) also failed: "
                     + ", ".join(f"{p} on {n} case(s)" for p, n in cx["also_failed"].items()))
    if not cx["confirmed_by_sweep"]:
        lines.append("NOTE: rbcheck sweep's gates do not fail on this file" + (
            "" if cx["sweep_gated"] else f" (they do not check {cx['property']}: "
                                         "run rbcheck fuzz or rbcheck check)"))
    wrapped = []
    for line in lines:
        while len(line) > 110:
            cut = line.rfind(" ", 0, 110)
            cut = cut if cut > 40 else 110
            wrapped.append(line[:cut])
            line = "  " + line[cut:].lstrip()
        wrapped.append(line)
    return generate.to_toml(cx["spec"], header="\n".join(wrapped))


# --- the campaign ------------------------------------------------------------------------------------------

def run_campaign(variants, out_dir, *, budget_s: float, seed: int = 0, jobs: int = 1, use_cache: bool = True,
                 executor=None, engine_files=(), log=None, finish=None) -> dict:
    """Search, shrink, confirm, and write DIR (``fuzz.json``, ``counterexamples/*.toml``; the caller adds the
    HTML page through ``finish(staging_dir)``, inside the atomic replacement). Returns the summary. Raises
    FuzzError on an unusable DIR."""
    from cross_checks.engines import resolve
    from cross_checks.sweep.cache import cache_dir
    from cross_checks.sweep.results_dir import (
        ResultsDirError,
        check_output_dir,
        replace_dir,
        staging_dir,
        write_marker,
    )
    variants = [resolve(v) for v in variants]   # once: the batches, the shrinking and the summary use these
    log = log or (lambda s: print(s, file=sys.stderr))
    try:
        out = check_output_dir(str(out_dir))
    except ResultsDirError as exc:
        raise FuzzError(str(exc)) from None
    started = datetime.now(UTC).replace(microsecond=0).isoformat()
    t0 = time.monotonic()
    seen = {"cases": 0, "bad": 0}

    def on_batch(r):
        seen["cases"] += len(r["cases"])
        seen["bad"] += sum(1 for c in r["cases"] if c["violations"])
        if r["batch"] % 10 == 0:
            log(f"rbcheck fuzz: {seen['cases']} cases in "
                f"{time.monotonic() - t0:.0f} s, {seen['bad']} with a violation")

    results = search(seed, variants, budget_s, jobs=jobs, executor=executor, cache_root=str(cache_dir()),
                     use_cache=use_cache, on_batch=on_batch)
    search_s = time.monotonic() - t0
    failures = _failures(results)
    counterexamples = []
    shrink_deadline = time.monotonic() + SHRINK_S * MAX_SHRUNK
    for failure in list(failures.values())[:MAX_SHRUNK]:
        counterexamples.append(_counterexample(failure, engine_files, shrink_deadline, log))
    unshrunk = [{"property": f["hits"][0][2]["property"], "variants": list(f["variants"]),
                 "cases": f["cases"], "explained": f["explained"],
                 "also_failed": f["also"],
                 "first": {"seed": f["hits"][0][0], "index": f["hits"][0][1],
                           "sentence": f["hits"][0][2]["sentence"]}}
                for f in list(failures.values())[MAX_SHRUNK:]]
    summary = _summary(results, variants, seed, budget_s, jobs, started, search_s, time.monotonic() - t0,
                       counterexamples, unshrunk)
    staging = staging_dir(out)
    try:
        _write(staging, summary, counterexamples)
        if finish is not None:
            finish(staging)
        write_marker(staging)
        replace_dir(staging, out)
    except BaseException:
        import shutil
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return summary


def _write(d: Path, summary, counterexamples) -> None:
    if counterexamples:
        (d / "counterexamples").mkdir()
    for cx, rec in zip(counterexamples, summary["counterexamples"]):
        atomic_write_text(d / rec["file"], _file_text(cx, rec["file"]))
    atomic_write_text(d / SUMMARY, json.dumps(summary, indent=1, ensure_ascii=False) + "\n")


def _summary(results, variants, seed, budget_s, jobs, started, search_s, wall_s, counterexamples, unshrunk):
    from cross_checks.engines import engine_provenance
    from cross_checks.sweep.results_dir import safe_file_stem
    tallies = _tallies(results, variants)
    n_cases = sum(len(r["cases"]) for r in results)
    skipped = [c for r in results for c in r["cases"] if "skipped" in c["numbers"]]
    cx_out = []
    for k, cx in enumerate(counterexamples):
        stem = safe_file_stem(f"{k + 1:02d}_{cx['property']}_{'_'.join(cx['variants'])}".replace(":", "-"))
        file = f"counterexamples/{stem}.toml"
        cx_out.append({**{key: cx[key] for key in cx if key != "spec"}, "file": file,
                       "reproduce": _reproduce_line(file, cx["variants"], cx["engine_files"])})
    return _clean({
        "format": FORMAT, "schema_version": 1,
        "provenance": {"started": started, "seed": seed, "budget_s": budget_s, "jobs": jobs,
                       "engines": {e: engine_provenance(e)
                                   for e in sorted({v.split(':', 1)[0] for v in variants})},
                       "batch": BATCH, "n0_cycle": list(N0_CYCLE)},
        "variants": list(variants),
        "cases": {"drawn": n_cases, "judged": n_cases - len(skipped), "skipped": len(skipped),
                  "batches": len(results), "cached_batches": sum(1 for r in results if r.get("cached")),
                  "search_s": search_s, "wall_s": wall_s,
                  "cases_per_s": (n_cases - len(skipped)) / search_s if search_s > 0 else None,
                  "case_variant_runs": sum(d["cases"] for d in tallies["per_variant"].values())},
        "skipped_reasons": sorted({c["numbers"]["skipped"].split(" = ")[0] for c in skipped}),
        "per_variant": tallies["per_variant"], "pairs": tallies["pairs"],
        "properties": {p: [sum(d["properties"][p][0] for d in tallies["per_variant"].values())
                           + sum(t[p][0] for t in tallies["pairs"].values()),
                           sum(d["properties"][p][1] for d in tallies["per_variant"].values())
                           + sum(t[p][1] for t in tallies["pairs"].values())] for p in P.PROPERTIES},
        "numbers": _numbers_seen(results),
        "violations": sum(len(c["violations"]) for r in results for c in r["cases"]),
        "cases_with_violations": sum(1 for r in results for c in r["cases"] if c["violations"]),
        "counterexamples": cx_out, "not_shrunk": unshrunk,
        "batch_errors": [{"batch": r["batch"], "error": r["error"]} for r in results if r.get("error")],
    })
