"""``rbcheck check``: a true verdict on any simulator's trajectory (docs/check.md).

``input`` reads and interprets the file (steps, precision, decimation), ``evidence`` (on the exact
flow of ``cross_checks.analysis.flow``) turns defects, conserved quantities and free-running errors
into evidence with derived allowances, ``diagnosis`` names the scheme or the classic mistake
(``mistakes``), ``verdict`` decides, ``ladder`` fits orders over several files, ``report`` prints."""
from cross_checks.gates.check.verdict import CheckError, CheckResult, check_trajectory

__all__ = ["CheckError", "CheckResult", "check_trajectory"]
