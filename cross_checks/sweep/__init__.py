"""``rbcheck sweep``: planning (``plan``), one job and its measurement (``jobs``), the verified cache
(``cache``), executors and signals (``lifecycle``), the results directory and its marker
(``results_dir``, ``schema``), assembling records and summary, and the orchestration (``run``)."""
from cross_checks.sweep.run import (LOCAL_SAMPLES, MAX_SERIES_POINTS, RESULT_COLUMNS, SCHEMA_VERSION, Job,
                                    SweepError, SweepInterrupted, cache_dir, plan_jobs, run_sweep)

__all__ = ["RESULT_COLUMNS", "SweepError", "SweepInterrupted", "Job", "plan_jobs", "run_sweep", "cache_dir",
           "MAX_SERIES_POINTS", "LOCAL_SAMPLES", "SCHEMA_VERSION"]
