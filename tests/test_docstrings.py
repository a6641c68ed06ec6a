"""The documentation keeps up with the code: meta-tests in the manner of python-control's.

* Every public module, class, function and method of ``onboard``, ``drivers`` and
  ``sitl`` has a docstring (a method may inherit its base's, as :func:`inspect.getdoc`
  finds it). Public: a name that does not start with ``_``, defined in the module that is
  checked (not imported into it).
* Where a docstring has an ``Args:`` (Google) or ``Parameters`` (numpy or Google) section,
  every name it lists is a parameter of the signature (``__init__``'s for a class).
* Every citation ``algorithms.md §N.M`` or ``architecture.md §N.M`` in the code, the tests,
  the README and the docs names a heading ``## N`` / ``### N.M`` that exists in that page
  under ``docs/``; so does every bare ``§N.M`` of a module that cites algorithms.md, unless
  the text just before it names another source (a paper, Sola, an arXiv number). Every
  ``docs/<name>.md`` path mentioned exists, and nothing points at design documents
  outside the repository.
* The command tables of the README and of docs/architecture.md §4.1 list exactly the
  subcommands of ``onboard --help``; the rooms table of docs/architecture.md §2 says
  what ``tests/test_layering.py`` enforces.

Each checker has a negative control: fed a module, function, docstring or text with the
defect, it reports it.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import inspect
import pkgutil
import re
import sys
import textwrap
import types
from pathlib import Path
from typing import Any, Iterator

import pytest

REPO = Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"
PACKAGES = ("onboard", "drivers", "sitl")


# --------------------------------------------------------------------------------------
# (a) docstrings exist


def _modules() -> list[types.ModuleType]:
    """Every module of the packages, imported (``__main__`` modules are skipped: they run
    the program)."""
    out = []
    for top in PACKAGES:
        pkg = importlib.import_module(top)
        out.append(pkg)
        for info in pkgutil.walk_packages(pkg.__path__, top + "."):
            if info.name.rpartition(".")[2] == "__main__":
                continue
            out.append(importlib.import_module(info.name))
    return out


def _is_public(name: str) -> bool:
    return not name.startswith("_")


def _own_function(obj: Any, module: str) -> Any | None:
    """The plain function behind ``obj`` (through ``functools`` wrappers) when it is
    defined in ``module``, else None."""
    fn = inspect.unwrap(obj) if callable(obj) else obj
    if inspect.isfunction(fn) and fn.__module__ == module:
        return fn
    return None


def _class_doc(cls: type) -> str | None:
    """The class's own docstring; None also for the signature text that ``dataclass``
    and ``NamedTuple`` write when there is none."""
    doc = cls.__dict__.get("__doc__")
    if not doc or re.fullmatch(re.escape(cls.__name__) + r"\(.*\)", doc.strip(), re.DOTALL):
        return None
    return doc


def _methods(cls: type) -> Iterator[tuple[str, Any]]:
    """``(name, attribute as found on the class)`` of the public methods and properties
    defined in the class body itself (a dataclass field whose default is a function, or
    a lambda stored as a class attribute, is data, not a method)."""
    fields = getattr(cls, "__dataclass_fields__", {})
    for name, raw in vars(cls).items():
        if not _is_public(name) or name in fields or getattr(raw, "__name__", "") == "<lambda>":
            continue
        if isinstance(raw, (staticmethod, classmethod)):
            raw = raw.__func__
        if isinstance(raw, property) or (callable(raw)
                                         and inspect.isfunction(inspect.unwrap(raw))):
            yield name, getattr(cls, name)


def missing_docstrings(module: types.ModuleType) -> list[str]:
    """Public objects of ``module`` without a docstring, as ``module.qualname``. A class
    needs its own; a method or property may inherit its base's (:func:`inspect.getdoc`)."""
    name = module.__name__
    missing = [] if inspect.getdoc(module) else [name]
    for attr, obj in sorted(vars(module).items()):
        if not _is_public(attr):
            continue
        if inspect.isclass(obj) and obj.__module__ == name:
            if _class_doc(obj) is None:
                missing.append(f"{name}.{obj.__qualname__}")
            missing += [f"{name}.{obj.__qualname__}.{meth}" for meth, value in _methods(obj)
                        if not inspect.getdoc(value)]
        elif _own_function(obj, name) is not None and not inspect.getdoc(obj):
            missing.append(f"{name}.{attr}")
    return missing


MODULES = _modules()


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.__name__)
def test_every_public_object_has_a_docstring(module: types.ModuleType) -> None:
    missing = missing_docstrings(module)
    assert not missing, "no docstring: " + ", ".join(missing)


def test_the_docstring_check_flags_what_lacks_one(monkeypatch: pytest.MonkeyPatch) -> None:
    """Negative control: a module whose module docstring, functions (a cached one too),
    classes (a dataclass and an exception, which would otherwise show generated or
    inherited text), methods and a property lack docstrings is reported on each; private
    names and inherited method docstrings are accepted."""
    probe = types.ModuleType("probe")
    source = textwrap.dedent('''
        import dataclasses
        import functools

        def bare(x):
            return x

        @functools.lru_cache(maxsize=None)
        def cached(n):
            return n

        def _private():
            return 0

        class Base:
            """A base."""

            def step(self):
                """Advance."""

        class Child(Base):
            def step(self):
                return 1

            def extra(self):
                return 2

            @property
            def value(self):
                return 3

        class Bare:
            """Documented class, undocumented static method."""

            @staticmethod
            def make():
                return Bare()

        @dataclasses.dataclass
        class Record:
            size: int
            convert: object = lambda x: x

        class Failure(ValueError):
            pass
    ''')
    monkeypatch.setitem(sys.modules, "probe", probe)   # where inspect looks for base classes
    exec(compile(source, "probe", "exec"), probe.__dict__)  # noqa: S102 - fixed test source
    assert missing_docstrings(probe) == [
        "probe", "probe.Bare.make", "probe.Child", "probe.Child.extra", "probe.Child.value",
        "probe.Failure", "probe.Record", "probe.bare", "probe.cached"]


# --------------------------------------------------------------------------------------
# (b) the names in Args / Parameters sections exist

_HEADER = re.compile(r"^(\s*)(Args|Arguments|Parameters|Keyword Args):?\s*$")
_SECTION = re.compile(r"^\s*(Returns|Raises|Yields|Attributes|Examples?|Notes?|See Also|"
                      r"References|Warnings?)\s*:?\s*$")
_ENTRY = re.compile(r"^(\*{0,2}\w+(?:\s*,\s*\*{0,2}\w+)*)\s*(?:\([^)]*\))?\s*:(?:\s|$)")


def documented_parameters(doc: str) -> list[str]:
    """The parameter names listed in a cleaned docstring's Args/Parameters sections."""
    lines = doc.splitlines()
    names: list[str] = []
    i = 0
    while i < len(lines):
        head = _HEADER.match(lines[i])
        i += 1
        if head is None:
            continue
        if i < len(lines) and re.fullmatch(r"\s*-{3,}\s*", lines[i]):   # numpy underline
            i += 1
        indent: int | None = None
        while i < len(lines):
            line = lines[i]
            if not line.strip() or _SECTION.match(line) or _HEADER.match(line):
                break
            width = len(line) - len(line.lstrip())
            if indent is None:
                indent = width
            if width < indent:
                break
            if width == indent:
                entry = _ENTRY.match(line.strip())
                if entry is None:
                    break
                names += [n.strip().lstrip("*") for n in entry.group(1).split(",")]
            i += 1
    return names


def _signature_names(obj: Any) -> tuple[set[str], bool]:
    """Parameter names of a function, or of a class's ``__init__``; and whether it takes
    ``**kwargs`` (then any documented keyword is accepted)."""
    target = obj.__init__ if inspect.isclass(obj) else obj
    try:
        params = inspect.signature(target).parameters.values()
    except (TypeError, ValueError):
        return set(), True
    return ({p.name for p in params},
            any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params))


def undocumented_names(obj: Any) -> list[str]:
    """Names in ``obj``'s own docstring's Args/Parameters sections that its signature
    lacks."""
    raw = obj.__doc__ if inspect.isclass(obj) else getattr(inspect.unwrap(obj), "__doc__",
                                                           None)
    if not raw:
        return []
    listed = documented_parameters(inspect.cleandoc(raw))
    names, var_kw = _signature_names(obj)
    return [] if var_kw else [n for n in listed if n not in names]


def _documented_callables(module: types.ModuleType) -> Iterator[tuple[str, Any]]:
    name = module.__name__
    for attr, obj in sorted(vars(module).items()):
        if inspect.isclass(obj) and obj.__module__ == name:
            yield f"{name}.{obj.__qualname__}", obj
            for meth, raw in vars(obj).items():
                if isinstance(raw, (staticmethod, classmethod)):
                    raw = raw.__func__
                fn = inspect.unwrap(raw) if callable(raw) else None
                if inspect.isfunction(fn):
                    yield f"{name}.{obj.__qualname__}.{meth}", fn
        elif _own_function(obj, name) is not None:
            yield f"{name}.{attr}", obj


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.__name__)
def test_documented_parameters_exist_in_the_signature(module: types.ModuleType) -> None:
    wrong = {q: bad for q, obj in _documented_callables(module)
             if (bad := undocumented_names(obj))}
    assert not wrong, "documented but not in the signature: " + "; ".join(
        f"{q}: {', '.join(bad)}" for q, bad in wrong.items())


def test_the_parameter_check_flags_a_name_the_signature_lacks() -> None:
    """Negative control: Google, comma-grouped and numpy-style sections, a class
    documented against ``__init__``; a renamed parameter is caught, ``**kwargs`` admits
    any keyword."""

    def google(alpha, beta, gamma=1):
        """Do it.

        Args:
            alpha, beta: the inputs (m).
            gama: a misspelt keyword.
                With a continuation line.

        Returns:
            nothing.
        """

    def numpy_style(source, rate):
        """Parse.

        Parameters
        ----------
        source:
            where it came from.
        speed : float
            renamed since.
        """

    def keywords(a, **kw):
        """Args:
            a: first.
            b: any keyword.
        """

    class Thing:
        """A thing.

        Parameters:
            size: how big.
            colour: not a parameter.
        """

        def __init__(self, size):
            self.size = size

    assert documented_parameters(inspect.cleandoc(google.__doc__)) == ["alpha", "beta", "gama"]
    assert undocumented_names(google) == ["gama"]
    assert undocumented_names(numpy_style) == ["speed"]
    assert undocumented_names(keywords) == []
    assert undocumented_names(Thing) == ["colour"]


# --------------------------------------------------------------------------------------
# (c) citations and document paths resolve

_NUM = r"\d+(?:\.\d+)*"
_CITE = re.compile(r"(algorithms|architecture)\.md`{0,2}\s*(?:§\s*|section\s+)?(" + _NUM +
                   r")(?:\s*[-–]\s*§?(" + _NUM + r"))?")
_BARE = re.compile(r"(?<![\w.§])§\s*(" + _NUM + r")")
_OTHER_SOURCE = re.compile(r"paper|Paper|Sola|arXiv|Tanner|Fossen|Prestero|"
                           r"\b(?!algorithms\.md)[\w-]+\.md\b")
_DOC_PATH = re.compile(r"docs/[\w./-]+?\.md\b")


def headings(page: Path) -> set[str]:
    """Section numbers of a page's ``## N ...`` / ``### N.M ...`` headings."""
    found = set()
    for line in page.read_text(encoding="utf-8").splitlines():
        m = re.match(r"^#{2,4}\s+(" + _NUM + r")\.?\s", line)
        if m:
            found.add(m.group(1))
    return found


def citations(text: str, bare: bool = True) -> list[tuple[str, str]]:
    """``(page, section)`` of every section citation in ``text``, in order: explicit ones
    (``algorithms.md §2.6``, ``architecture.md section 4``, ``algorithms.md 4.3``, ranges
    ``§3.1-§3.2``) and, with ``bare`` and where ``algorithms.md`` is cited at all, every
    other ``§N.M`` that the 80 characters before it attribute to no other source."""
    found: list[tuple[int, str, str]] = []
    taken: list[tuple[int, int]] = []
    for m in _CITE.finditer(text):
        page = f"{m.group(1)}.md"
        found += [(m.start(g), page, m.group(g)) for g in (2, 3) if m.group(g)]
        taken.append(m.span())
    if bare and "algorithms.md" in text:
        for m in _BARE.finditer(text):
            if any(a <= m.start() < b for a, b in taken):
                continue
            before = re.sub(r"\s+", " ", text[max(0, m.start() - 160):m.start()])[-80:]
            if not _OTHER_SOURCE.search(before):
                found.append((m.start(1), "algorithms.md", m.group(1)))
    return [(page, sec) for _, page, sec in sorted(found)]


def broken_citations(text: str, bare: bool = True) -> list[str]:
    """Citations in ``text`` whose section is not a heading of the page under docs/."""
    have = {page: headings(DOCS / page) for page in ("algorithms.md", "architecture.md")}
    return [f"{page} §{sec}" for page, sec in citations(text, bare) if sec not in have[page]]


def _citing_files() -> list[Path]:
    files = [p for top in (*PACKAGES, "tests") for p in sorted((REPO / top).rglob("*.py"))
             if p.name != Path(__file__).name]
    return files + [REPO / "README.md"] + sorted(DOCS.glob("*.md"))


@pytest.mark.parametrize("path", _citing_files(), ids=lambda p: str(p.relative_to(REPO)))
def test_section_citations_name_existing_headings(path: Path) -> None:
    # a page's own bare section signs refer to itself: only algorithms.md's are checked
    bare = path.suffix == ".py" or path == DOCS / "algorithms.md"
    assert broken_citations(path.read_text(encoding="utf-8"), bare) == []


@pytest.mark.parametrize("path", _citing_files(), ids=lambda p: str(p.relative_to(REPO)))
def test_mentioned_doc_pages_exist_and_none_lies_outside_the_repository(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    missing = sorted({p for p in _DOC_PATH.findall(text) if not (REPO / p).is_file()})
    assert missing == []
    assert "shared/design" not in text, "cite docs/algorithms.md or docs/architecture.md"


_LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
_REPO_PATH = re.compile(r"(?<![\w/.-])((?:onboard|drivers|sitl|tests|config|systemd)/"
                        r"[\w./-]*?\.(?:py|toml|json|service))\b(?!\.)")
_DOTTED = re.compile(r"(?<![\w/.-])((?:onboard|drivers|sitl)(?:\.[A-Za-z_]\w*)+)")
_NOT_MODULES = {"py", "toml", "json", "md", "png", "service", "txt", "csv", "tlog", "bin",
                "onbrec", "json5", "html", "egg"}


def dotted_name_resolves(dotted: str) -> bool:
    """Whether ``a.b.c`` names a module of the repository, or a name that the longest such
    module prefix defines or imports."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        base = REPO.joinpath(*parts[:i])
        source = base.with_suffix(".py") if base.with_suffix(".py").is_file() \
            else base / "__init__.py"
        if source.is_file():
            rest = parts[i:]
            return not rest or re.search(rf"\b{re.escape(rest[0])}\b",
                                         source.read_text(encoding="utf-8")) is not None
    return False


def _is_schema_name(dotted: str) -> bool:
    """A wire schema name (``onboard.Estimate.v1``, ``onboard.Health.v2``:
    onboard/core/wire.py), not a module: its second part is capitalized, as no package
    of ours is."""
    parts = dotted.split(".")
    return len(parts) >= 2 and parts[1][:1].isupper()


def stale_references(page: Path) -> list[str]:
    """Links, repository paths and dotted module names of a Markdown page that do not
    exist (links relative to the page, paths to the repository root)."""
    text = page.read_text(encoding="utf-8")
    bad = [link for link in _LINK.findall(text)
           if "://" not in link and not (page.parent / link).exists()]
    bad += [p for p in _REPO_PATH.findall(text) if not (REPO / p).is_file()]
    bad += [d for d in _DOTTED.findall(text)
            if d.rpartition(".")[2] not in _NOT_MODULES and not _is_schema_name(d)
            and not dotted_name_resolves(d)]
    return sorted(set(bad))


@pytest.mark.parametrize("page", [REPO / "README.md", *sorted(DOCS.glob("*.md"))],
                         ids=lambda p: str(p.relative_to(REPO)))
def test_pages_name_only_files_and_modules_that_exist(page: Path) -> None:
    assert stale_references(page) == []


def test_the_citation_check_flags_missing_sections_and_pages(tmp_path: Path) -> None:
    """Negative control: explicit, ranged, 'section' and bare citations are found; a bare
    paragraph sign after a paper's name is not taken for algorithms.md; stale links,
    paths and module names on a page are reported."""
    text = ("Bare §1.2 counts, as does §99.9, but not the paper's §3.3 nor (Sola, §6.3)"
            " nor aie.md §7.7.\n"
            "See algorithms.md §2.6 and algorithms.md section 4.1; architecture.md §4.2.\n"
            "The ranges algorithms.md §3.1-§3.2 and (algorithms.md\n 4.3) too.")
    assert citations(text) == [
        ("algorithms.md", "1.2"), ("algorithms.md", "99.9"),
        ("algorithms.md", "2.6"), ("algorithms.md", "4.1"), ("architecture.md", "4.2"),
        ("algorithms.md", "3.1"), ("algorithms.md", "3.2"), ("algorithms.md", "4.3")]
    assert broken_citations(text) == ["algorithms.md §99.9"]
    assert broken_citations(text, bare=False) == []
    assert broken_citations("architecture.md §9.9") == ["architecture.md §9.9"]
    assert citations("no page named, so the bare §9.9 is someone else's") == []
    assert _DOC_PATH.findall("read docs/nothing-here.md and docs/aie.md.") == [
        "docs/nothing-here.md", "docs/aie.md"]
    page = tmp_path / "page.md"
    page.write_text("[gone](gone.md), `onboard/pipelines/aie_pipeline.py`, "
                    "`onboard.reports.aie_validation`, `onboard.engine.NoSuchThing`; fine: "
                    f"[here]({page.name}), `onboard/engine/engine.py`, `onboard.engine.Engine`, "
                    "`/etc/onboard/onboard.toml`.\n")
    assert stale_references(page) == ["gone.md", "onboard.engine.NoSuchThing",
                                      "onboard.reports.aie_validation",
                                      "onboard/pipelines/aie_pipeline.py"]


# --------------------------------------------------------------------------------------
# (d) the command tables and the rooms table


def _section(page: Path, heading: str) -> str:
    """The text of the section whose heading line starts with ``heading``, up to the next
    heading of the same or a higher level."""
    lines = page.read_text(encoding="utf-8").splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(heading))
    level = len(heading) - len(heading.lstrip("#"))
    end = next((i for i in range(start + 1, len(lines))
                if re.match(r"^#{1,%d}\s" % level, lines[i])), len(lines))
    return "\n".join(lines[start + 1:end])


def table_commands(text: str) -> set[str]:
    """Subcommand names of the table rows that start with ``| `onboard NAME``."""
    return set(re.findall(r"^\|\s*`onboard ([a-z][\w-]*)", text, flags=re.MULTILINE))


def cli_commands() -> set[str]:
    """The subcommands ``onboard --help`` offers."""
    from onboard.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return set(sub.choices)


@pytest.mark.parametrize("page, heading", [("README.md", "## Commands"),
                                           ("docs/architecture.md", "### 4.1 ")])
def test_command_tables_list_the_cli_subcommands(page: str, heading: str) -> None:
    assert table_commands(_section(REPO / page, heading)) == cli_commands()


def test_the_help_text_names_every_subcommand() -> None:
    from onboard.cli import build_parser

    text = build_parser().format_help()
    assert all(re.search(rf"^\s+{name}\s", text, re.MULTILINE) for name in cli_commands())


def test_the_sitl_help_names_both_forms_of_dvl() -> None:
    """``--dvl`` takes ``tcp:HOST:PORT`` (Water Linked JSON) or ``pty`` (PD6), as
    docs/sitl.md's emitter table says; its help names both."""
    import argparse

    from onboard.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    text = " ".join(sub.choices["sitl"].format_help().split())
    assert "tcp:HOST:PORT|pty" in text and "PD6" in text, text


def test_the_command_table_check_sees_a_missing_row() -> None:
    """Negative control: a table without ``bench`` differs from the CLI."""
    rows = "\n".join(f"| `onboard {c} ...` | x |" for c in sorted(cli_commands() - {"bench"}))
    assert table_commands(rows) == cli_commands() - {"bench"}
    assert table_commands(rows) != cli_commands()


def layering_rooms() -> dict[str, set[str]]:
    """``ROOMS`` of ``tests/test_layering.py``, read from its source: the module-level
    assignments up to and including ``ROOMS`` are evaluated (set expressions of module
    names), so no test module is imported."""
    tree = ast.parse((REPO / "tests" / "test_layering.py").read_text(encoding="utf-8"))
    body = []
    for node in tree.body:
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            body.append(ast.Assign(targets=node.targets if isinstance(node, ast.Assign)
                                   else [node.target], value=node.value, lineno=0))
            if any(isinstance(t, ast.Name) and t.id == "ROOMS" for t in body[-1].targets):
                break
    namespace: dict[str, Any] = {}
    exec(compile(ast.fix_missing_locations(ast.Module(body=body, type_ignores=[])),  # noqa: S102
                 "test_layering.py", "exec"), {"__builtins__": {"set": set}}, namespace)
    return namespace["ROOMS"]


def _reduced(room: str, allowed: set[str]) -> set[str]:
    """``allowed`` without the room itself and without prefixes another entry covers."""
    rest = {a for a in allowed if a != room}
    return {a for a in rest if not any(a.startswith(b + ".") for b in rest)}


def rooms_table(text: str) -> dict[str, set[str]]:
    """Room -> the rooms its row says it may import (``nothing of ours``: none)."""
    out = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or not re.fullmatch(r"`[\w.]+`", cells[0]):
            continue
        out[cells[0].strip("`")] = set(re.findall(r"`([\w.]+)`", cells[2]))
    return out


def test_the_rooms_table_says_what_the_layering_test_enforces() -> None:
    rooms = layering_rooms()
    table = rooms_table(_section(DOCS / "architecture.md", "## 2. "))
    assert set(table) == set(rooms)
    differ = {room: (sorted(table[room] - {room}), sorted(_reduced(room, allowed)))
              for room, allowed in rooms.items()
              if table[room] - {room} != _reduced(room, allowed)}
    assert differ == {}


def test_the_rooms_check_sees_a_wrong_row() -> None:
    """Negative control: a row that lets the estimators import the engine is told apart."""
    row = "| `onboard.estimators` | math | `onboard.core`, `onboard.engine` |"
    assert rooms_table(row) == {"onboard.estimators": {"onboard.core", "onboard.engine"}}
    assert rooms_table(row)["onboard.estimators"] != _reduced(
        "onboard.estimators", layering_rooms()["onboard.estimators"])


def test_source_files_parse() -> None:
    """Every source file the checks above read is valid Python (a syntax error would
    otherwise surface only as an import failure of the whole module list)."""
    for top in PACKAGES:
        for path in (REPO / top).rglob("*.py"):
            ast.parse(path.read_text(encoding="utf-8"), str(path))
