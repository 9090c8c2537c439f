"""rbcheck's validation machinery, in layers that import only downwards (README, "Layout"):

``core`` (tolerances, quantities and their error metrics, the trajectory CSV, atomic files) →
``scenario`` (the TOML schema, the catalog, limits, the resolved JSON, each scenario's reference) →
``engines`` (one adapter interface, the registry, the built-in and user engines) →
``analysis`` (metrics, conservation, convergence fits, expectations decided by physics) →
``sweep`` (planning, jobs, the cache, executors, the results directory) →
``gates`` (``compare`` of results directories, ``check`` of a trajectory) →
``cli``, ``testing`` and ``pytest_plugin`` (the interfaces, which compose the layers with ``reports``).
``tests/test_architecture.py`` enforces the direction.
"""
