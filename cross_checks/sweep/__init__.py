"""``rbcheck sweep``, in the order its stages run (``run``): planning (``plan``), executing the references
and jobs here, in a pool or on an executor (``execute``), one job and its measurement (``jobs``),
assembling rows, records and summary (``assemble``, ``provenance``); the verified cache (``cache``) and
what its keys hold (``fingerprint``); workers, signals and time limits (``lifecycle``); the results
directory and its marker (``results_dir``, ``schema``)."""
from cross_checks.sweep.run import (
                                    LOCAL_SAMPLES,
                                    MAX_SERIES_POINTS,
                                    RESULT_COLUMNS,
                                    SCHEMA_VERSION,
                                    Job,
                                    SweepError,
                                    SweepInterrupted,
                                    cache_dir,
                                    plan_jobs,
                                    run_sweep,
)

__all__ = ["RESULT_COLUMNS", "SweepError", "SweepInterrupted", "Job", "plan_jobs", "run_sweep", "cache_dir",
           "MAX_SERIES_POINTS", "LOCAL_SAMPLES", "SCHEMA_VERSION"]
