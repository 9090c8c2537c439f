"""Where the repository's own files are, for tests at any depth of tests/."""
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "baselines" / "default"
