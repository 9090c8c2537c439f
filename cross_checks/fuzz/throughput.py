"""Fuzz throughput for ``rbcheck bench``: cases per second per engine, measured in one run.

One batch per n0 of the cycle (one with ``quick``) of campaign seed 0, every available reference,
MuJoCo and PyBullet variant: the seconds each variant spent running the batch's cases (free runs at
three rungs and one-step runs) and checking their properties, and the seconds the batch spent choosing
its steps and solving the exact motions (shared by every variant). Ratios are against MuJoCo measured
in the same run. The CPU seconds of the batches (``time.process_time``,
not disturbed by other work on a shared machine) give the cases a 10-minute campaign on 2 idle cores
would judge if its two workers (``--jobs 2``: one batch per core) each kept one core's rate — an upper
bound (docs/fuzz.md §4).
"""
from __future__ import annotations

import time

__all__ = ["fuzz_throughput", "format_fuzz"]


def fuzz_throughput(quick: bool = False) -> dict:
    from cross_checks.engines import available_variants
    from cross_checks.fuzz.campaign import BATCH, N0_CYCLE, compute_batch
    variants = [v for v in available_variants() if v.split(":")[0] in ("reference", "mujoco", "pybullet")]
    batches = [1] if quick else list(range(len(N0_CYCLE)))
    seconds = {v: 0.0 for v in variants}
    judged, wall, cpu = 0, 0.0, 0.0
    compute_batch(0, 0, variants[:1])   # imports, engine connections: once per worker, not per batch
    for b in batches:
        t0, c0 = time.perf_counter(), time.process_time()
        r = compute_batch(0, b, variants)
        wall += time.perf_counter() - t0
        cpu += time.process_time() - c0
        judged += sum(1 for c in r["cases"] if "skipped" not in c["numbers"])
        for v, s in r["seconds"].items():
            seconds[v] += s
    engines = {}
    for v, s in seconds.items():
        e = v.split(":")[0]
        d = engines.setdefault(e, {"variants": 0, "seconds": 0.0})
        d["variants"] += 1
        d["seconds"] += s
    for d in engines.values():
        d["case_variants_per_s"] = judged * d["variants"] / d["seconds"] if d["seconds"] > 0 else None
    mj = engines.get("mujoco", {}).get("case_variants_per_s")
    for d in engines.values():
        d["vs_mujoco"] = d["case_variants_per_s"] / mj if mj and d["case_variants_per_s"] else None
    shared = wall - sum(seconds.values())
    return {"batches": len(batches), "cases": judged, "batch": BATCH, "wall_s": wall, "cpu_s": cpu,
            "shared_s": shared, "cases_per_s_all_variants": judged / wall if wall > 0 else None,
            "cases_per_cpu_s": judged / cpu if cpu > 0 else None,
            "campaign_cases_600s_2_cores": 2 * 600.0 * judged / cpu if cpu > 0 else None,
            "case_variants_per_s": judged * len(variants) / wall if wall > 0 else None,
            "per_variant_cases_per_s": {v: judged / s if s > 0 else None for v, s in seconds.items()},
            "per_engine": engines}


def format_fuzz(r: dict) -> str:
    out = [f"fuzz: {r['cases']} cases x {len(r['per_variant_cases_per_s'])} variants in "
           f"{r['wall_s']:.1f} s on one core: {r['cases_per_s_all_variants']:.2f} cases/s through "
           f"every variant, {r['case_variants_per_s']:.1f} case-variant judgments/s "
           f"({r['shared_s']:.1f} s choosing steps and solving the exact motions)",
           f"fuzz: {r['cases_per_cpu_s']:.2f} cases per CPU second ({r['cpu_s']:.1f} s): a "
           f"600 s budget on 2 idle cores would judge ~{r['campaign_cases_600s_2_cores']:,.0f} "
           "cases through every variant if its two workers ran at one core's rate each (a "
           "real campaign's own count is what to quote, docs/fuzz.md section 4)"]
    out.append(f"{'fuzz engine':<12} {'case-variants/s':>16} {'vs MuJoCo':>10}")
    for e, d in r["per_engine"].items():
        ratio = f"{d['vs_mujoco']:.2f}x" if d["vs_mujoco"] else "-"
        out.append(f"{e:<12} {d['case_variants_per_s']:>16.1f} {ratio:>10}")
    return "\n".join(out)
