"""rbcheck's reference simulator: the GAMES103 rigid-body equations in NumPy (imports no engine).

Modules: ``quaternion`` (w, x, y, z algebra), ``body`` (mass properties), ``forces``, ``state``,
``integrators`` (every variant, batched), ``simulate`` (recorded runs with divergence detection),
``analytic`` (closed forms), ``ground_truth`` (DOP853).
"""
__version__ = "0.1.0"
