"""What the numbers mean: conservation and drift metrics and round-off floors (``metrics``), convergence
fits (``convergence``), the expected verdict of every (scenario, variant, quantity) decided from the
variant's traits and the scenario's measured physics (``expectations``, ``physics``), and the exact flow
from any recorded state with the one-step allowance of a consistent scheme (``flow``)."""
