"""Rapier's step of one body, timed alone, with k floats of Python work made between steps, in a world with a
pool of one worker of its own (``set_num_threads(1)``, what rbcheck's worlds had until 2026-11-29) and on the
calling thread (``set_num_threads(None)``, rayon's global pool, which rapier3d gives no work for a few bodies:
what a world of up to worlds.rapier.OWN_POOL_ABOVE bodies does now). docs/speed.md, "Where it stands".

With a pool of its own every step is handed to the worker and back: ~20 us with nothing between steps (the
worker still spinning), ~45-60 us with 1000 floats between (asleep, woken). On the calling thread: ~3 us, the
same with or without work between steps.

    python benchmarks/rapier_step_between.py
"""
import time

from cross_checks import bench

N_STEPS = 5000


def step_us(world, y0, k: int) -> float:
    """µs per ``PhysicsWorld.step()`` of the bench's body over N_STEPS, a list of ``k`` floats built between
    steps (outside the timing)."""
    world.set_state(y0[None])
    inside = 0.0
    for _ in range(N_STEPS):
        if k:
            _ = [float(i) for i in range(k)]
        t0 = time.perf_counter()
        world.world.step()
        inside += time.perf_counter() - t0
    return inside / N_STEPS * 1e6


if __name__ == "__main__":
    world, y0 = bench._own_world("rapier", "symplectic_euler")   # the adapter's world of the bench's body
    try:
        for threads, label in ((1, "a pool of one of its own"), (None, "the calling thread")):
            world.world.set_num_threads(threads)
            for k in (0, 50, 200, 1000, 0):
                print(f"{label:>24}: {k:5d} floats between steps: {step_us(world, y0, k):6.1f} us per step")
    finally:
        world.close()
