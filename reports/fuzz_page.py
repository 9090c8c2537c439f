"""The HTML page of an ``rbcheck fuzz`` directory, rendered from its summary FILE only (``fuzz.json``,
docs/fuzz.md): it never imports the fuzzer or an engine. ``render_fuzz(DIR)`` writes ``DIR/index.html``.
"""
from __future__ import annotations

import json
from pathlib import Path

from reports.data import ResultsError

__all__ = ["render_fuzz", "FUZZ_SUMMARY"]

FUZZ_SUMMARY = "fuzz.json"
_FORMAT = "rbcheck fuzz summary"
_NUMBERS = {"hL": "h·L (step × fastest rate)", "chi": "χ = ½ L² h T (first-order drift)",
            "amplification": "A (measured error amplification)", "A_chi": "A·χ (linearity)",
            "anisotropy": "(I_max − I_min) / I_max", "separatrix_proximity": "distance from the separatrix",
            "stiffness_dt2_per_m": "k Δt² / m"}


def _g(v, fmt="{:.3g}") -> str:
    return "–" if v is None else fmt.format(v)


def _load(d: Path) -> dict:
    path = d / FUZZ_SUMMARY
    try:
        s = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ResultsError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    except ValueError as exc:
        raise ResultsError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(s, dict) or s.get("format") != _FORMAT:
        raise ResultsError(f"{path}: field 'format': not an rbcheck fuzz summary")
    return s


def _context(s: dict) -> dict:
    props = list(s["properties"])
    rows = [{"name": v, "cases": d["cases"], "seconds": _g(d["seconds"], "{:.1f}"),
             "rate": _g(d["cases_per_s"], "{:.1f}"),
             "props": [f"{d['properties'][p][0]} / {d['properties'][p][1]}" for p in props]}
            for v, d in s["per_variant"].items()]
    rows += [{"name": pair, "cases": "", "seconds": "", "rate": "",
              "props": [f"{t[p][0]} / {t[p][1]}" for p in props]} for pair, t in s.get("pairs", {}).items()]
    numbers = [{"name": _NUMBERS.get(k, k), "min": _g(v["min"]),
                "median": _g(v["median"]), "max": _g(v["max"])}
               for k, v in s["numbers"].items() if k != "kinds"]
    kinds = [{"name": k, "text": ", ".join(f"{n} {c}" for n, c in sorted(v.items(), key=lambda kv: -kv[1]))}
             for k, v in s["numbers"].get("kinds", {}).items()]
    c = s["cases"]
    n_cx = len(s["counterexamples"]) + len(s.get("not_shrunk", []))
    verdict = (f"{c['judged']} cases judged ({c['skipped']} skipped as outside the fairness bounds) on "
               f"{len(s['variants'])} variant(s), {c['case_variant_runs']} case × variant judgments in "
               f"{c['search_s']:.0f} s ({_g(c['cases_per_s'], '{:.2f}')} cases/s): "
               + (f"{n_cx} distinct failure(s) — exit 1." if n_cx else "no property violated — exit 0."))
    p = s["provenance"]
    prov = [("seed", p["seed"]), ("budget", f"{p['budget_s']} s"),
            ("jobs", p["jobs"]), ("started", p["started"]),
            ("batches",
             f"{c['batches']} of {p['batch']} cases ({c['cached_batches']} "
             f"from the cache), n0 cycle {p['n0_cycle']}")]
    prov += [(f"engine {e}", info.get("version", "")) for e, info in p["engines"].items()]
    return {"title": f"rbcheck fuzz — seed {p['seed']}", "nav": [], "provenance": prov,
            "verdict_text": verdict, "counterexamples": s["counterexamples"],
            "not_shrunk": s.get("not_shrunk", []), "rows": rows, "properties": props, "numbers": numbers,
            "kinds": kinds, "batch_errors": s.get("batch_errors", [])}


def render_fuzz(directory) -> Path:
    """Write ``DIR/index.html`` from ``DIR/fuzz.json``; ResultsError when that is not a fuzz summary."""
    from cross_checks.core.files import atomic_write_text
    from reports.html import environment
    d = Path(directory)
    html = environment().get_template("fuzz.html").render(**_context(_load(d)))
    out = d / "index.html"
    atomic_write_text(out, html)
    return out
