"""The fuzz targets' scratch directory: file readers are fuzzed through real files."""

from __future__ import annotations

import atexit
import shutil
import tempfile
from pathlib import Path

SCRATCH = Path(tempfile.mkdtemp(prefix="onboard-fuzz-"))
"""A fresh temporary directory per test process; its files are overwritten per input,
and it is removed when the process exits."""
atexit.register(shutil.rmtree, SCRATCH, ignore_errors=True)
