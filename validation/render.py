"""The one template mechanism of the generated tables: Markdown templates under
``validation/templates/`` filled from ``docs/figures.json`` (and ``docs/tuning.json``).

A page's template mirrors its path: ``validation/templates/README.md`` holds the README's
generated blocks, ``validation/templates/docs/aie.md`` those of ``docs/aie.md``. A template
holds blocks only, each one Markdown table between two markers, exactly as the page shows
it but with placeholders where the numbers go::

    <!-- figures:begin KEY: generated from docs/figures.json by ...; the template is ... -->
    | scenario | AIE speed (m/s) |
    |---|---|
    | jaiabot-turns | {aie.jaiabot_turns.speed_rmse.aie} |
    <!-- figures:end KEY -->

The marker's family says where the values come from: ``figures`` blocks from the figures
file's ``figures`` object, ``tuning`` blocks from the records of ``docs/tuning.json``
(:func:`validation.tuning.records`). ``KEY`` names the block within its family (the
README's figures block and the tuning block have none). Filling a page replaces each of its
blocks, markers included, with the template's block rendered, and leaves every other byte.

A record is ``{"values": {seed: value or null}, "digits": N}`` (``N`` decimals, or ``"Ng"``:
N significant digits). The placeholders (docs/reproducing.md):

* ``{name}``: the value at the record's digits, or its range ``lo-hi`` over the seeds when
  they differ at those digits; ``n/a`` when never published (``null``);
* ``{name@2}``: its value on seed 2;
* ``{name:4}``, ``{name@2:4}``: with 4 decimals; ``{name:2g}``: with 2 significant digits;
* ``{seeds(name)}``: the seeds it is measured on (``1-3``, ``1, 4``, ``-``);
* ``{below_raw(a, b, raw)}``: which of figures ``a``, ``b`` are below ``raw`` on every
  seed: ``both``, ``A only`` (the last part of the name in capitals: ``...speed_rmse.aie``
  is ``AIE``), ``B only`` or ``**neither**``;
* ``{ratio(num, den)}``: ``num / den`` on their common seeds, printed as a value (2
  decimals unless ``:N``);
* ``{chi2_band(counts, dim)}``, ``{chi2_band(counts@1, dim)}``: ``[lo, hi]``, the two-sided
  95 % band of the mean of ``n`` chi-square(``dim``) values, ``n`` the sum of the count
  figure over its seeds (or on one seed), 3 decimals unless ``:N``.

Any other brace in a block is an error. A body row without a placeholder must end with
:data:`QUOTED` (a row of numbers quoted from a paper; the comment is not printed): every
other number of a generated table is the file's.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence, Union

from onboard.core.errors import UsageError

TEMPLATES = Path(__file__).resolve().parent / "templates"
"""The templates: ``README.md`` for the README, ``docs/NAME.md`` for the docs page of that
name."""
README_TEMPLATE = TEMPLATES / "README.md"
DOCS_TEMPLATES = TEMPLATES / "docs"

SOURCES = {"figures": "docs/figures.json", "tuning": "docs/tuning.json"}
"""The block families and the file each one's values come from."""
QUOTED = " <!-- quoted -->"
"""The end of a template row of numbers quoted from a paper (no figure of ours)."""

Records = Mapping[str, Mapping[str, Any]]

# ----------------------------------------------------------------------------- values


def _values(rec: Mapping[str, Any], seed: str | None) -> list[float]:
    if seed is None:
        return [v for v in rec["values"].values() if v is not None]
    if seed not in rec["values"]:
        raise UsageError(f"a template asks for seed {seed} of a figure measured on "
                         f"{', '.join(rec['values'])}")
    v = rec["values"][seed]
    return [] if v is None else [v]


def format_value(rec: Mapping[str, Any], seed: str | None = None, spec: str | None = None
                 ) -> str:
    """A record's value as the tables print it: on ``seed``, or its range ``lo-hi`` over
    the seeds when they differ at the printed digits; ``n/a`` when never published.
    ``spec`` (default the record's ``digits``): ``"3"`` three decimals, ``"2g"`` two
    significant digits."""
    spec = str(rec["digits"]) if spec is None else spec
    fmt = f".{spec[:-1]}g" if spec.endswith("g") else f".{spec}f"
    vals = _values(rec, seed)
    if not vals:
        return "n/a"
    lo, hi = format(min(vals), fmt), format(max(vals), fmt)
    return lo if lo == hi else f"{lo}-{hi}"


@dataclass(frozen=True)
class Ref:
    """A figure named in a placeholder, on one seed or (``seed`` None) on all of them."""

    name: str
    seed: str | None = None

    def record(self, records: Records) -> Mapping[str, Any]:
        """The figure's record; a :class:`UsageError` when the records lack it."""
        if self.name not in records:
            raise UsageError(f"a template names {self.name}, which the file lacks (run "
                             f"python -m validation figures --only {self.name} --write "
                             "docs/figures.json, or tune for a tuning.* name)")
        return records[self.name]


_REF = r"[a-z][a-z0-9_.]*(?:@\d+)?"
_SPEC = r"\d+g?"
PLACEHOLDER = re.compile(rf"\{{(?:(?P<func>[a-z0-9_]+)\((?P<args>[^(){{}}]*)\)|(?P<ref>{_REF}))"
                         rf"(?::(?P<spec>{_SPEC}))?\}}")
"""``{ref[:spec]}`` or ``{function(arg, ...)[:spec]}``, ``ref`` ``name`` or ``name@seed``."""
_ARG = re.compile(rf"(?P<int>\d+)|(?P<ref>{_REF})")
_BRACED = re.compile(r"(\{[^{}]*\})")


def _ref(text: str) -> Ref:
    name, _, seed = text.partition("@")
    return Ref(name, seed or None)


def _arg(text: str) -> Ref | int:
    m = _ARG.fullmatch(text.strip())
    if m is None:
        raise UsageError(f"{text!r} is neither a figure nor a number")
    return int(m["int"]) if m["int"] else _ref(m["ref"])


# ----------------------------------------------------------------------------- functions

Arg = Union[Ref, int]


def _seeds(records: Records, ref: Ref) -> str:
    seeds = sorted(int(s) for s in ref.record(records)["values"] if s != "-")
    if not seeds:
        return "-"
    if seeds == list(range(seeds[0], seeds[-1] + 1)) and len(seeds) > 1:
        return f"{seeds[0]}-{seeds[-1]}"
    return ", ".join(str(s) for s in seeds)


def _below_raw(records: Records, first: Ref, second: Ref, raw_ref: Ref) -> str:
    raw = raw_ref.record(records)["values"]

    def below(ref: Ref) -> bool:
        return all(v is not None and raw.get(k) is not None and v < raw[k]
                   for k, v in ref.record(records)["values"].items())

    a, b = below(first), below(second)
    if a and b:
        return "both"
    if a or b:
        return f"{(first if a else second).name.rpartition('.')[2].upper()} only"
    return "**neither**"


def _ratio(records: Records, num: Ref, den: Ref, spec: str | None = None) -> str:
    a, b = num.record(records)["values"], den.record(records)["values"]
    r = [a[k] / b[k] for k in a if k in b and a[k] is not None and b[k]]
    return format_value({"values": dict(enumerate(r)), "digits": 2}, spec=spec)


def _chi2_band(records: Records, counts: Ref, dim: int, spec: str | None = None) -> str:
    from validation.reports.runs import chi2_mean_band

    values = counts.record(records)["values"]
    keys = [counts.seed] if counts.seed else list(values)
    missing = [k for k in keys if values.get(k) is None]
    if missing:
        raise UsageError(f"{counts.name} lacks a count on seed(s) {', '.join(missing)}")
    lo, hi = chi2_mean_band(int(sum(values[k] for k in keys)), dim)
    return "[{}, {}]".format(*(format_value({"values": {"-": v}, "digits": 3}, spec=spec)
                               for v in (lo, hi)))


FUNCTIONS: dict[str, tuple[Callable[..., str], tuple[type, ...], bool]] = {
    "seeds": (_seeds, (Ref,), False),
    "below_raw": (_below_raw, (Ref, Ref, Ref), False),
    "ratio": (_ratio, (Ref, Ref), True),
    "chi2_band": (_chi2_band, (Ref, int), True),
}
"""Each function: (what computes it, its argument kinds, whether it takes a ``:spec``)."""


def _call(func: str, args: Sequence[Arg], spec: str | None, records: Records) -> str:
    if func not in FUNCTIONS:
        raise UsageError(f"{func}() is not a template function ({', '.join(FUNCTIONS)})")
    fn, kinds, takes_spec = FUNCTIONS[func]
    if len(args) != len(kinds) or not all(isinstance(a, k) for a, k in zip(args, kinds)):
        raise UsageError(f"{func}() takes {len(kinds)} argument(s): "
                         + ", ".join("a figure" if k is Ref else "a number" for k in kinds))
    if spec is not None and not takes_spec:
        raise UsageError(f"{func}() prints no number, it takes no :{spec}")
    return fn(records, *args, **({"spec": spec} if spec is not None else {}))


# ----------------------------------------------------------------------------- placeholders


def _placeholder(text: str) -> re.Match[str]:
    m = PLACEHOLDER.fullmatch(text)
    if m is None:
        raise UsageError(f"{text} is not a placeholder (docs/reproducing.md)")
    return m


def _pieces(text: str) -> list[str]:
    """``text`` split into literal text (even indices) and placeholders (odd); a brace
    outside a placeholder is a :class:`UsageError`."""
    parts = _BRACED.split(text)
    for i, part in enumerate(parts):
        if i % 2 == 0 and ("{" in part or "}" in part):
            raise UsageError(f"a stray brace in {text!r}")
        if i % 2:
            _placeholder(part)
    return parts


def fill(text: str, records: Records) -> str:
    """``text`` with every placeholder replaced by its value from ``records``."""
    out = []
    for i, part in enumerate(_pieces(text)):
        if i % 2 == 0:
            out.append(part)
            continue
        m = _placeholder(part)
        if m["ref"]:
            ref = _ref(m["ref"])
            out.append(format_value(ref.record(records), ref.seed, m["spec"]))
        else:
            args = [_arg(a) for a in m["args"].split(",")] if m["args"].strip() else []
            out.append(_call(m["func"], args, m["spec"], records))
    return "".join(out)


def names(text: str) -> set[str]:
    """Every figure name the placeholders of ``text`` read."""
    out: set[str] = set()
    for i, part in enumerate(_pieces(text)):
        if i % 2:
            m = _placeholder(part)
            refs = [m["ref"]] if m["ref"] else [a for a in m["args"].split(",")]
            out |= {a.name for a in map(_arg, refs) if isinstance(a, Ref)}
    return out


# ----------------------------------------------------------------------------- blocks

_BEGIN = re.compile(r"<!-- (?P<family>[a-z]+):begin(?: (?P<key>[\w.-]+))?:[^\n]*-->")


@dataclass(frozen=True)
class Block:
    """One generated block of a template: its family (:data:`SOURCES`), key (``""`` for
    none) and text, markers included."""

    family: str
    key: str
    text: str

    @property
    def ident(self) -> str:
        """``family key`` (or the family alone): how messages name the block."""
        return f"{self.family} {self.key}".strip()

    def begin(self) -> str:
        """The opening marker, as the template writes it."""
        return self.text.split("\n", 1)[0]

    def end(self) -> str:
        """The closing marker."""
        return f"<!-- {self.family}:end{' ' + self.key if self.key else ''} -->"

    def body(self) -> list[str]:
        """The table's lines between the markers."""
        return self.text.split("\n")[1:-1]

    def names(self) -> set[str]:
        """Every figure the block reads."""
        return set().union(*(names(line) for line in self.body()))

    def render(self, records: Records) -> str:
        """The block as the page shows it (markers included), filled from ``records``."""
        lines = [fill(line.removesuffix(QUOTED), records) for line in self.body()]
        return "\n".join([self.begin(), *lines, self.end()])

    def find(self, text: str, where: str = "the page") -> str:
        """This block in a page's text (markers included); a :class:`UsageError` when its
        markers are missing or repeated."""
        opening = f"<!-- {self.family}:begin{' ' + self.key if self.key else ''}:"
        i, j = text.find(opening), text.find(self.end())
        if i < 0 or j < i or text.count(opening) != 1 or text.count(self.end()) != 1:
            raise UsageError(f"{where} has no single generated block {self.ident} (its "
                             f"{opening} ... --> / {self.end()} markers)")
        return text[i:j + len(self.end())]


def _check_table(block: Block, where: str) -> None:
    """A block holds one Markdown table: a header, its separator and rows of as many
    cells, each row with a placeholder unless marked :data:`QUOTED`."""
    body = block.body()
    if len(body) < 2 or not re.fullmatch(r"\|(---\|)+", body[1]):
        raise UsageError(f"{where}, block {block.ident}: not a Markdown table")
    width = body[0].count("|")
    for line in body[2:]:
        if not line.startswith("|") or line.removesuffix(QUOTED).count("|") != width:
            raise UsageError(f"{where}, block {block.ident}: a row of other than "
                             f"{width - 1} cells: {line[:60]}")
        if not line.endswith(QUOTED) and not _BRACED.search(line):
            raise UsageError(f"{where}, block {block.ident}: a row without a figure "
                             f"(end it with '{QUOTED.strip()}' if it quotes a paper): "
                             f"{line[:60]}")
        names(line)


def parse(text: str, where: str = "the template") -> list[Block]:
    """The blocks of a template's text; a :class:`UsageError` for text outside them, an
    unknown family, a block without its end marker or not a table."""
    blocks: list[Block] = []
    pos = 0
    for m in _BEGIN.finditer(text):
        if text[pos:m.start()].strip():
            raise UsageError(f"{where}: text outside a generated block: "
                             f"{text[pos:m.start()].strip()[:60]}")
        family, key = m["family"], m["key"] or ""
        if family not in SOURCES:
            raise UsageError(f"{where}: unknown block family {family} ({', '.join(SOURCES)})")
        block = Block(family, key, "")
        j = text.find(block.end(), m.end())
        if j < 0:
            raise UsageError(f"{where}: block {block.ident} has no {block.end()}")
        pos = j + len(block.end())
        block = Block(family, key, text[m.start():pos])
        _check_table(block, where)
        blocks.append(block)
    if text[pos:].strip():
        raise UsageError(f"{where}: text outside a generated block: {text[pos:].strip()[:60]}")
    return blocks


def template_blocks(path: Path, family: str | None = None) -> list[Block]:
    """The blocks of the template file ``path`` (of ``family`` only, when given)."""
    if not path.is_file():
        raise UsageError(f"{path}: no such template")
    blocks = parse(path.read_text(encoding="utf-8"), str(path))
    return [b for b in blocks if family in (None, b.family)]


def templates() -> list[Path]:
    """Every template file, the README's first."""
    return [README_TEMPLATE, *sorted(DOCS_TEMPLATES.glob("*.md"))]


def page_of(template: Path) -> str:
    """The page a template fills, relative to the repository (``docs/aie.md``)."""
    return template.relative_to(TEMPLATES).as_posix()


# ----------------------------------------------------------------------------- pages


def update_page(page: Path, template: Path, family: str, records: Records) -> list[str]:
    """Rewrite the ``family`` blocks of ``page`` from ``template`` filled with
    ``records``; returns the blocks that changed (:attr:`Block.ident`)."""
    if not page.is_file():
        raise UsageError(f"{page}: no such page")
    text = page.read_text(encoding="utf-8")
    new, changed = text, []
    for block in template_blocks(template, family):
        old, rendered = block.find(new, str(page)), block.render(records)
        if old != rendered:
            changed.append(block.ident)
            new = new.replace(old, rendered)
    if new != text:
        page.write_text(new, encoding="utf-8")
    return changed


def update_docs(docs_dir: Path, family: str, records: Records) -> list[str]:
    """Rewrite the ``family`` blocks of every page in ``docs_dir`` that has a template
    (``validation/templates/docs/PAGE.md``); returns the blocks that changed."""
    changed = []
    for template in sorted(DOCS_TEMPLATES.glob("*.md")):
        if template_blocks(template, family):
            changed += update_page(docs_dir / template.name, template, family, records)
    return changed
