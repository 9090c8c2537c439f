"""Rapier's step of one body, timed alone, with k floats of Python work made between steps (docs/speed.md,
"Where it stands": its step grows from ~20 µs with nothing between steps to ~50 µs with 1000 floats).

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
        for k in (0, 50, 200, 1000, 0):
            print(f"{k:5d} floats between steps: {step_us(world, y0, k):6.1f} us per step")
    finally:
        world.close()
