"""Bit-identity snapshot of engine runs: run it before and after a change to an engine adapter or the host
loop, and compare the two files with ``--diff``: every catalog scenario (plus this folder's extra scenarios: a
planar particle body in a non-principal frame with every force kind, its non-planar twin, a fast tumble) x
every variant of the given engines x its Δt ladder (runs capped at 4000 steps), through ``simulate_many``,
``simulate`` (first Δt, 1500 steps) and ``one_step`` (8 rows of that run). Each entry is a digest of the
states' bytes, the times' bytes, the divergence time and the message.

    python benchmarks/bit_identity/snapshot.py before.json mujoco pybullet
    python benchmarks/bit_identity/snapshot.py after.json mujoco pybullet
    python benchmarks/bit_identity/snapshot.py --diff before.json after.json

``--scenarios a,b,...`` (catalog names or this folder's extras by stem, e.g. ``skew``) restricts the snapshot
to those scenarios, for an engine too slow for all of them under load: give the same to both snapshots.
"""
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from cross_checks.engines import get_adapter
from cross_checks.engines.base import EngineError, RunRequest
from cross_checks.scenario.parse import catalog_names, load_scenario

EXTRA = sorted(str(p) for p in Path(__file__).parent.glob("*.toml"))


def _digest(a) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()[:16]


def _entry(run) -> str:
    if isinstance(run, BaseException):
        return f"ERR {type(run).__name__}: {run}"
    return (f"{_digest(run.y)} n={len(run.y)} div={run.diverged_at_s!r} msg={run.message!r} "
            f"t={_digest(run.t_s)[:8]}")


def snapshot(engines, only=None) -> dict:
    names = [n for n in catalog_names() + EXTRA if only is None or Path(n).stem in only]
    out = {}
    for eng in engines:
        ad = get_adapter(eng)
        for v in ad.variants:
            reqs = [RunRequest(sc, dt, min(int(round(sc.duration_s / dt)), 4000))
                    for sc in map(load_scenario, names) if not ad.expressible(sc, v)
                    for dt in sc.dt_ladder_s]
            for r, run in zip(reqs, ad.simulate_many(v, reqs)):
                out[f"{eng}:{v}|{r.scenario.name}|{r.dt_s!r}|many"] = _entry(run)
            seen = set()
            for r in reqs:
                if r.scenario.name in seen:
                    continue
                seen.add(r.scenario.name)
                try:
                    run = ad.simulate(r.scenario, v, r.dt_s, min(r.n_steps, 1500))
                except EngineError as exc:
                    run = exc
                out[f"{eng}:{v}|{r.scenario.name}|{r.dt_s!r}|single"] = _entry(run)
                if ad.has_one_step and not isinstance(run, BaseException):
                    rows = run.y[::max(1, len(run.y) // 7)][:8]
                    try:
                        y1 = ad.one_step(r.scenario, v, r.dt_s, rows)
                        out[f"{eng}:{v}|{r.scenario.name}|one_step"] = _digest(y1)
                    except EngineError as exc:
                        out[f"{eng}:{v}|{r.scenario.name}|one_step"] = f"ERR {exc}"
    return out


def main(argv) -> int:
    if not argv or argv[0] in ("-h", "--help") or (argv[0] != "--diff" and (argv[0].startswith("-")
                                                                           or len(argv) < 2)):
        print(__doc__.strip().splitlines()[0] + "\n\nusage: snapshot.py OUT.json ENGINE [ENGINE ...] "
              "[--scenarios a,b]\n       snapshot.py --diff BEFORE.json AFTER.json", file=sys.stderr)
        return 0 if argv[:1] in (["-h"], ["--help"]) else 2
    if argv[:1] == ["--diff"]:
        a, b = (json.loads(Path(p).read_text()) for p in argv[1:3])
        engines = {k.split(":", 1)[0] for k in b}      # the engines the second file holds
        keys = {k for k in set(a) | set(b) if k.split(":", 1)[0] in engines}
        bad = sorted(k for k in keys if a.get(k) != b.get(k))
        print(f"{len(keys)} entries, {len(bad)} differ")
        for k in bad[:20]:
            print(f"{k}\n  before: {a.get(k)}\n  after:  {b.get(k)}")
        return 1 if bad else 0
    only = None
    if "--scenarios" in argv:
        i = argv.index("--scenarios")
        only, argv = set(argv[i + 1].split(",")), argv[:i] + argv[i + 2:]
    out = snapshot(argv[1:], only)
    Path(argv[0]).write_text(json.dumps(out, indent=0, sort_keys=True))
    print(len(out), "entries")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
