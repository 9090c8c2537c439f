"""The bottom layer: every tolerance (``tolerances``), the four quantities and their error metrics
(``quantities``), the trajectory CSV contract (``trajectory``), atomic file writes (``files``) and the
rule of names and keys users write (``names``). Imports nothing of rbcheck but ``reference_sim``."""
