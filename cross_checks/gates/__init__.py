"""Verdicts on what users bring: ``compare`` (a results directory against a baseline) and ``check`` (any
simulator's trajectory CSV against a scenario)."""
