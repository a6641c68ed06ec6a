"""The fuzz targets' scratch directory: file readers are fuzzed through real files."""

from __future__ import annotations

import tempfile
from pathlib import Path

SCRATCH = Path(tempfile.mkdtemp(prefix="onboard-fuzz-"))
"""A fresh temporary directory per test process; its files are overwritten per input."""
