"""The configuration shown on the web page, and the file it may edit.

The service runs with ``--config FILE [--config OVERLAY ...]``; the page shows every
file and the configuration they make, and, with ``service.web.edit_config``, edits the
last file: a new text is checked exactly as ``onboard run`` would load it (TOML, the
schema with dotted-key errors, the deployment checks of
:func:`onboard.service.config_check.check_config`) together with the files before it,
and is saved (atomically, the previous text kept as ``FILE.bak``) only when it passes.
The running service is not changed: the new file applies at its next start.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import Sequence

from onboard.core.config import ConfigError, load_all, resolve, to_dict
from onboard.service.config_check import check_config


class ConfigEditor:
    """The configuration files of the running service.

    Parameters:
        paths: the ``--config`` files in order (the last one is the editable one).
        editable: whether :meth:`save` may write it.
    """

    def __init__(self, paths: Sequence[str | Path], editable: bool) -> None:
        self.paths = [resolve(p) for p in paths]
        self.editable = editable and bool(self.paths)

    @property
    def target(self) -> Path | None:
        """The file the page edits (the last ``--config``)."""
        return self.paths[-1] if self.paths else None

    def show(self) -> dict:
        """Every file's text, the one the page may edit, and the configuration in use."""
        files = []
        for p in self.paths:
            try:
                files.append({"path": str(p), "text": p.read_text()})
            except OSError as err:
                files.append({"path": str(p), "text": "", "error": err.strerror})
        try:
            effective = to_dict(load_all(self.paths)) if self.paths else None
        except ConfigError as err:
            effective = {"error": str(err)}
        return {"files": files, "editable": self.editable,
                "target": str(self.target) if self.target else None, "effective": effective}

    def check(self, text: str) -> list[str]:
        """What is wrong with ``text`` as the new last file (empty: nothing)."""
        target = self.target
        if target is None:
            return ["the service was started without a configuration file"]
        with tempfile.TemporaryDirectory(prefix="onboard-config-") as tmp:
            candidate = Path(tmp) / target.name
            candidate.write_text(text)
            try:
                cfg = load_all([*self.paths[:-1], candidate])
                check_config(cfg, str(target))
            except ConfigError as err:
                return [str(err).replace(str(candidate), str(target))]
        return []

    def save(self, text: str) -> list[str]:
        """Check ``text`` and, when it passes, write it over the last file (the old one
        kept as ``.bak``); the errors otherwise (a check's or the disk's)."""
        if not self.editable:
            return ["editing is off: set service.web.edit_config = true"]
        errors = self.check(text)
        if errors:
            return errors
        target = self.target
        assert target is not None
        tmp = None
        try:
            fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.")
            with os.fdopen(fd, "w") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.chmod(tmp, target.stat().st_mode & 0o777)
            shutil.copy2(target, target.with_name(target.name + ".bak"))
            os.replace(tmp, target)
        except OSError as err:
            if tmp is not None and os.path.exists(tmp):
                os.unlink(tmp)
            return [f"{target}: cannot write: {err.strerror}"]
        return []
