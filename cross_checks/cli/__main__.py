"""``python -m cross_checks.cli`` = the ``rbcheck`` command."""
import sys

from cross_checks.cli import main

sys.exit(main())
