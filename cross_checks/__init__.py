"""rbcheck's validation machinery, in layers that import only downwards: core → scenario → engines →
analysis → sweep → gates, reports, bench, fuzz → cli, testing → pytest_plugin (README, "Layout";
``tests/test_architecture.py`` enforces the direction).
"""
