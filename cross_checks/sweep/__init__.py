"""``rbcheck sweep``: its stages in order in :mod:`cross_checks.sweep.run`, each module's part in the README,
"Layout"."""
from cross_checks.sweep.run import (
                                    LOCAL_SAMPLES,
                                    MAX_SERIES_POINTS,
                                    RESULT_COLUMNS,
                                    SCHEMA_VERSION,
                                    Job,
                                    ReportFailed,
                                    SweepError,
                                    SweepInterrupted,
                                    cache_dir,
                                    plan_jobs,
                                    run_sweep,
)

__all__ = ["RESULT_COLUMNS", "SweepError", "SweepInterrupted", "ReportFailed", "Job", "plan_jobs",
           "run_sweep", "cache_dir", "MAX_SERIES_POINTS", "LOCAL_SAMPLES", "SCHEMA_VERSION"]
