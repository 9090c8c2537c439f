"""The compiled JAX engines' batched throughput through rbcheck against their own vmapped loop, alternately.

    python -m benchmarks.jax_batched [--pairs 5] [--bodies 1000] [--steps 100]

For MJX, Brax and jaxsim (those installed): the engine's own run of ``rbcheck bench`` (cross_checks.bench's
``OWN_BATCHED``: N bodies vmapped through one compiled ``fori_loop`` of the engine's step, nothing recorded)
and
N runs of the bench's body through the adapter's ``simulate_many`` (``bench.adapter_batched``: every state
recorded, the forces the harness's), measured one after the other ``--pairs`` times in this process, so that
the machine's load moves both alike. Prints the medians of each, their [min, max], the ratio of the medians
(issue 43's goal: at least 0.5) and the range of the per-pair ratios (docs/speed.md, "The compiled engines'
loop with the forces inside it").
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import statistics

ENGINES = (("mjx", "euler", "mujoco.mjx"), ("brax", "generalized", "brax"),
           ("jaxsim", "semi_implicit_euler", "jaxsim"))


def measure(pairs: int, n_bodies: int, n_steps: int) -> list:
    from cross_checks import bench
    rows = []
    for engine, variant, module in ENGINES:
        if importlib.util.find_spec(module) is None:
            continue
        own, through = [], []
        for _ in range(pairs):
            own.append(bench.OWN_BATCHED[engine](n_bodies, n_steps, 1, variant)["median"])
            through.append(bench.adapter_batched(f"{engine}:{variant}", n_bodies, n_steps, 1)["median"])
        rows.append({"variant": f"{engine}:{variant}", "own": own, "rbcheck": through})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--bodies", type=int, default=1000)
    ap.add_argument("--steps", type=int, default=100)
    args = ap.parse_args(argv)
    print(f"N = {args.bodies} bodies, {args.steps} steps, {args.pairs} pairs; load average at the start "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores", flush=True)
    print(f"{'body-steps/s':28s} {'engine (own loop)':>30s} {'through rbcheck':>30s} {'ratio':>6s}  per pair")
    for r in measure(args.pairs, args.bodies, args.steps):
        own, rb = r["own"], r["rbcheck"]
        mo, mr = statistics.median(own), statistics.median(rb)
        pair = [b / a for a, b in zip(own, rb)]
        print(f"{r['variant']:28s} {mo:10.3e} [{min(own):.2e}, {max(own):.2e}] "
              f"{mr:10.3e} [{min(rb):.2e}, {max(rb):.2e}] {mr / mo:6.2f}  {min(pair):.2f}-{max(pair):.2f}",
              flush=True)
    print(f"load average at the end {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
