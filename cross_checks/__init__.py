"""rbcheck's validation machinery, in layers that import only downwards (README, "Layout"):

``core`` (tolerances, quantities and their error metrics, the trajectory CSV, atomic files) →
``scenario`` (the TOML schema, the catalog, limits, the resolved JSON, each scenario's reference) →
``engines`` (one adapter interface, the registry, the built-in and user engines) →
``analysis`` (metrics, conservation, convergence fits, expectations decided by physics) →
``sweep`` (planning, jobs, the cache, executors, the results directory) →
``gates`` (``compare`` of results directories, ``check`` of a trajectory), beside ``reports`` (the
top-level package that draws a results directory) and ``bench`` →
``cli`` and ``testing`` (the interfaces: the only modules that compose sweep, report and bench) →
``pytest_plugin`` (the ``assert_engine`` fixture over ``testing``).
``tests/test_architecture.py`` enforces the direction.
"""
