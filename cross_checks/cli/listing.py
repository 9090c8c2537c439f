"""``rbcheck list``: the catalog, the long runs and every engine variant (``--json``: machine-readable).

(Named ``listing``, not ``list``: importing a submodule binds its name in the package's namespace, where
``list`` would hide the builtin.)"""
from __future__ import annotations

import sys

from cross_checks.cli.errors import EXIT_OK


def _list_json() -> str:
    """``rbcheck list --json``: the catalog and every variant, machine-readable."""
    import json

    from cross_checks.engines import all_variants
    from cross_checks.scenario import catalog_names, load_scenario, long_run_names

    scenarios = []
    for name in catalog_names():
        sc = load_scenario(name)
        scenarios.append({"name": sc.name, "description": sc.description, "reference": sc.reference,
                          "duration_s": sc.duration_s, "dt_s": sc.dt_s, "dt_ladder_s": list(sc.dt_ladder_s)})
    variants = []
    for v in all_variants():
        variants.append({"name": v.name, "engine": v.engine, "variant": v.variant, "available": v.available,
                         "reason": v.reason, "version": v.version, "declared_order": v.order,
                         "description": v.description, "source": v.source,
                         "default": v.default})
    long_runs = []
    for name in long_run_names():
        sc = load_scenario(name)
        long_runs.append({"name": sc.name, "description": sc.description, "kind": sc.kind,
                          "duration_s": sc.duration_s, "dt_s": sc.dt_s})
    return json.dumps({"scenarios": scenarios, "long_runs": long_runs, "variants": variants}, indent=1)


def cmd_list(args) -> int:
    from cross_checks.engines import all_variants
    from cross_checks.scenario import catalog_names, load_scenario, long_run_names

    if args.json:
        print(_list_json())
        return EXIT_OK
    print("Scenarios (catalog):")
    for name in catalog_names():
        sc = load_scenario(name)
        print(f"  {name:<18} {sc.description}")
    print("\nLong runs (in the default sweep; with SCENARIOs named: rbcheck sweep --long, or by name):")
    for name in long_run_names():
        sc = load_scenario(name)
        print(f"  {name:<22} {sc.description}")
    print("\nEngine variants:")
    shown = set()
    for v in all_variants():
        if v.engine not in shown and not v.source.endswith("(rbcheck)"):
            print(f"  {v.engine}: from {v.source}")
        shown.add(v.engine)
        state = f"available ({v.engine} {v.version})" if v.available else f"UNAVAILABLE: {v.reason}"
        if v.default:
            state += f"; the default: run --engine {v.engine}"
        print(f"  {v.name:<26} {state}")
        text = v.description + (f" (order {v.order:g})" if v.order is not None else "")
        if text:
            print(f"  {'':<26} {text.strip()}")
    from cross_checks.engines import unusable_required_engines
    for engine, why in unusable_required_engines().items():
        print(f"rbcheck list: warning: {engine} is required by rbcheck and cannot run here ({why}): "
              "sweep and fuzz exit 2 until it is reinstalled", file=sys.stderr)
    return EXIT_OK
