"""``rbcheck check``: a true verdict on any simulator's trajectory (docs/check.md).

``input`` reads and interprets the file (steps, precision, decimation), ``flow`` advances the exact
flow from recorded states, ``evidence`` turns defects, conserved quantities and free-running errors
into evidence with derived allowances, ``diagnosis`` names the scheme or the classic mistake
(``mistakes``), ``verdict`` decides, ``ladder`` fits orders over several files, ``report`` prints."""
from cross_checks.gates.check.verdict import CheckError, CheckResult, check_trajectory

__all__ = ["CheckError", "CheckResult", "check_trajectory"]
