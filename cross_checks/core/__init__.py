"""The bottom layer: every tolerance (``tolerances``), the four quantities and their error metrics
(``quantities``), the trajectory CSV contract (``trajectory``) and atomic file writes (``files``).
Imports nothing of rbcheck but ``reference_sim``."""
