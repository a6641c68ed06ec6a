"""Reading the project's own imports from its source, for the layering tests.

Imports are read with :mod:`ast`, inside functions too (a lazy import is still a dependency
at run time), and so are module names given to ``importlib.import_module`` as string
literals. Imports under ``if TYPE_CHECKING:`` are type hints only and do not count.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
OURS = {"onboard"}
"""The top-level package of this repository."""
INSTALLED_AS = {"drivers": "onboard.drivers", "sitl": "onboard.sitl", "config": "onboard.bundled"}
"""Top-level folders installed as subpackages of ``onboard`` (pyproject.toml); ``config/``
is data only (the bundled configs and gains)."""


def module_name(path: Path) -> str:
    """The module a source file is imported as (``drivers/nmea.py``: ``onboard.drivers.nmea``)."""
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    name = ".".join(parts)
    top, _, rest = name.partition(".")
    if top in INSTALLED_AS:
        return INSTALLED_AS[top] + (f".{rest}" if rest else "")
    return name


def source_path(module: str) -> Path | None:
    """The source file of ``module`` in this repository (a package: its ``__init__.py``),
    None when there is none (``onboard.drivers.nmea``: ``drivers/nmea.py``)."""
    for folder, installed in INSTALLED_AS.items():
        if module == installed or module.startswith(installed + "."):
            module = folder + module[len(installed):]
    base = REPO / Path(*module.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def imports_of(path: Path, module: str | None = None, *, ours: set[str] = OURS,
               type_hints: bool = False) -> list[tuple[int, str]]:
    """(line, module) for every import in ``path`` (named ``module``, by default from its
    place in the repository) of a module under the top-level names ``ours``, lazy ones
    included; those under ``if TYPE_CHECKING:`` too when ``type_hints``."""
    module = module or module_name(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    tree = ast.parse(path.read_text(), str(path))
    skip: set[int] = set()
    for node in ast.walk(tree):
        if not type_hints and isinstance(node, ast.If) and _is_type_checking(node):
            skip.update(id(n) for child in node.body for n in ast.walk(child))
    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            # ``from pkg import mod`` names the submodule when there is one
            for a in node.names:
                sub = f"{base}.{a.name}"
                found.append((node.lineno, sub if source_path(sub) is not None else base))
        elif (isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "import_module"
              and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)):
            found.append((node.lineno, node.args[0].value))
    return [(line, m) for line, m in found if m.split(".")[0] in ours]
