"""The docs name only what exists: every dotted ``pbf.`` or ``benchmarks.`` name in docs/*.md, README.md
and CONTRIBUTING.md resolves (its module imports and each attribute after it exists; after
``python -m`` it is a module), and every repo-relative path they mention (``benchmarks/ab.py``, ``docs/VALIDATION.md``,
``pbf/solver/grid.py``, ``tests/test_x.py::test_name``, a Markdown link) exists. A renamed module, a
removed function or a moved file fails here with the file and line of each stale reference.

Not checked: CHANGELOG.md and docs/HISTORY_BENCHMARKS.md, which record what was (their names may be of
code since gone), and paths outside the repository (``/tmp/…``, ``../shared/…``)."""

import ast
import importlib
import importlib.util
import inspect
import re
import textwrap
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
HISTORY = {"docs/HISTORY_BENCHMARKS.md"}
"""Docs of what was tried, by topic, naming the code of their time (as CHANGELOG.md does)."""
DOCS = sorted(
    [ROOT / "README.md", ROOT / "CONTRIBUTING.md"]
    + [p for p in (ROOT / "docs").glob("*.md") if p.relative_to(ROOT).as_posix() not in HISTORY]
)

ROOTS = ("pbf", "tests", "benchmarks", "docs", "scenes", ".ci", "out")
"""A path is repo-relative when it starts with one of these folders."""
NOT_FILES = {
    "out/": "what the program and the studies write (out/dam_break, out/start.csv, …), made by the run",
}
"""Paths that legitimately name no file of the checkout, by prefix, and why."""

DOTTED = re.compile(r"(?<![\w./-])(python -m )?((?:pbf|benchmarks)(?:\.[A-Za-z_]\w*)+)")
PATH = re.compile(r"(?<![\w./~$<>:-])((?:" + "|".join(re.escape(r) for r in ROOTS) + r")/[\w./*<>-]*[\w*/])(::\w+)?")
LINK = re.compile(r"\]\(([^)\s#]+)(?:#([^)]*))?\)")
SECTION = re.compile(r"([\w/]*\b[A-Z][A-Z_]+\.md)`?\)?,? \"([^\"]+)\"")
"""A section named after its document: ``docs/BENCHMARKS.md, "On a GPU"`` (a heading that starts so)."""
NAMED = re.compile(r"(?<![\w./:-])([A-Z][A-Z_]+\.md|LICENSE|run\.py|pyproject\.toml)(?![\w/-])")
"""A document or top-level file named alone: ``METHOD.md`` beside docs/METHOD.md, ``run.py``."""


def lines(path: Path):
    yield from enumerate(path.read_text(encoding="utf-8").splitlines(), start=1)


@cache
def is_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:
        return False


def assigned_on_self(cls: type, name: str) -> bool:
    """Whether an instance attribute ``name`` is set in the class's own code (``self.name = …``)."""
    for klass in cls.__mro__:
        if not klass.__module__.startswith("pbf"):
            continue
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError, SyntaxError):
            continue
        for node in ast.walk(tree):
            targets = node.targets if isinstance(node, ast.Assign) else [getattr(node, "target", None)]
            for target in targets:
                if isinstance(target, ast.Attribute) and target.attr == name:
                    if isinstance(target.value, ast.Name) and target.value.id == "self":
                        return True
    return False


def has_attribute(owner, name: str) -> bool:
    if hasattr(owner, name):
        return True
    if inspect.isclass(owner):
        fields = getattr(owner, "__dataclass_fields__", {}) or {}
        annotations = {}
        for klass in owner.__mro__:
            annotations.update(getattr(klass, "__annotations__", {}))
        return name in fields or name in annotations or assigned_on_self(owner, name)
    return False


@cache
def why_stale(name: str, as_module: bool) -> str | None:
    """Why the dotted ``name`` does not resolve, or None when it does."""
    parts = name.split(".")
    depth = 1
    while depth < len(parts) and is_module(".".join(parts[: depth + 1])):
        depth += 1
    module_name = ".".join(parts[:depth])
    if as_module and depth < len(parts):
        return f"`python -m {name}`: {'.'.join(parts[: depth + 1])} is not a module"
    try:
        owner = importlib.import_module(module_name)
    except Exception as error:  # an import that fails is what the test reports
        return f"import {module_name} fails: {type(error).__name__}: {error}"
    for index in range(depth, len(parts)):
        if not has_attribute(owner, parts[index]):
            return f"{'.'.join(parts[:index])} has no attribute {parts[index]!r}"
        owner = getattr(owner, parts[index], None)
    return None


def path_stale(text: str, base: Path) -> str | None:
    """Why the path ``text`` (relative to ``base``) names nothing, or None when it does."""
    target = (base / text).resolve()
    if "*" in text:
        return None if list(base.glob(text)) else "matches no file"
    return None if target.exists() else "no such file or folder"


def headings(path: Path) -> list[str]:
    return [line.lstrip("#").strip() for _, line in lines(path) if re.match(r"#{1,4} ", line)]


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-")


def section_stale(document: Path, section: str | None, anchor: str | None) -> str | None:
    if not document.is_file() or document.suffix != ".md":
        return None  # the path itself is checked apart
    if section is not None and not any(h.startswith(section) for h in headings(document)):
        return f"{document.name} has no section {section!r}"
    if anchor is not None and anchor not in {slug(h) for h in headings(document)}:
        return f"{document.name} has no heading #{anchor}"
    return None


def references(path: Path, folder: Path | None = None):
    """(line, what, why stale) for each stale reference of ``path``, whose links are relative to
    ``folder`` (its own by default)."""
    folder = folder or path.parent
    for number, line in lines(path):
        for match in DOTTED.finditer(line):
            why = why_stale(match.group(2), bool(match.group(1)))
            if why:
                yield number, match.group(2), why
        for match in PATH.finditer(line):
            text, test = match.group(1), match.group(2)
            if any(text.startswith(prefix) for prefix in NOT_FILES) or "<" in text:
                continue
            why = path_stale(text, ROOT)
            if why is None and test:
                source = (ROOT / text).read_text(encoding="utf-8")
                if not re.search(rf"^\s*(?:def|class) {test[2:]}\b", source, flags=re.MULTILINE):
                    why = f"holds no test {test[2:]}"
            if why:
                yield number, text + (test or ""), why
        for match in LINK.finditer(line):
            target = match.group(1)
            if re.match(r"[a-z]+:", target):
                continue  # a URL
            why = path_stale(target, folder) or section_stale((folder / target).resolve(), None, match.group(2))
            if why:
                yield number, f"link ({target}{'#' + match.group(2) if match.group(2) else ''})", why
        for match in SECTION.finditer(line):
            name, section = match.groups()
            document = next((d for d in (folder / name, ROOT / name, ROOT / "docs" / name) if d.is_file()), None)
            why = section_stale(document, section, None) if document else None
            if why:
                yield number, f'{name}, "{section}"', why
        for match in NAMED.finditer(line):
            name = match.group(1)
            if not (folder / name).exists() and not (ROOT / name).exists():
                yield number, name, "no such file here or at the root"


def test_the_documents_are_found():
    names = {p.relative_to(ROOT).as_posix() for p in DOCS}
    assert {"README.md", "CONTRIBUTING.md", "docs/METHOD.md", "docs/BENCHMARKS.md"} <= names
    assert not HISTORY & names


@pytest.mark.parametrize(
    ("line", "found"),
    [
        ("see `pbf.solver.grid.NeighbourGrid`.", ["pbf.solver.grid.NeighbourGrid"]),
        ("`python -m pbf.study.sweep --flow`", ["pbf.study.sweep"]),
        ("pip install pbf-fluids; pbf_buckets.txt; the pbf command.", []),
    ],
)
def test_dotted_names_are_found_in_text(line, found):
    assert [m.group(2) for m in DOTTED.finditer(line)] == found


@pytest.mark.parametrize(
    ("name", "as_module", "stale"),
    [
        ("pbf.solver.grid.NeighbourGrid", False, False),
        ("pbf.study.sweep", True, False),
        ("pbf.Simulation", False, False),
        ("pbf.solver.grid.NoSuchGrid", False, True),
        ("pbf.solver.no_such_module", False, True),
        ("pbf.solver.Simulation", True, True),  # an attribute, not a module to run
    ],
)
def test_a_dotted_name_resolves_only_when_it_exists(name, as_module, stale):
    assert (why_stale(name, as_module) is not None) == stale


@pytest.mark.parametrize(
    ("line", "found"),
    [
        ("run `benchmarks/ab.py` (docs/VALIDATION.md).", ["benchmarks/ab.py", "docs/VALIDATION.md"]),
        ("`pbf/scenes/*.toml`, tests/test_mesh.py::test_x", ["pbf/scenes/*.toml", "tests/test_mesh.py"]),
        ("/tmp/pbf/x.py, https://github.com/a/docs/x.md, `git show abc123:scenes/x.toml`", []),
    ],
)
def test_paths_are_found_in_text(line, found):
    assert [m.group(1) for m in PATH.finditer(line)] == found


def test_a_stale_path_and_a_missing_test_are_found(tmp_path):
    fake = tmp_path / "doc.md"
    fake.write_text(
        "`benchmarks/no_such.py`, `tests/test_readme.py::test_nothing_here`, [x](nowhere.md), in NOWHERE.md\n"
        "as METHOD.md says, and README.md, `pbf/solver/grid.py`, [y](BENCHMARKS.md#bodies): all there\n"
        '(docs/BENCHMARKS.md, "On a GPU"), (`docs/METHOD.md`, "No such part"), [z](METHOD.md#no-such-part)\n'
    )
    found = [(what, why) for _, what, why in references(fake, ROOT / "docs")]
    assert [what for what, _ in found] == [
        "benchmarks/no_such.py",
        "tests/test_readme.py::test_nothing_here",
        "link (nowhere.md)",
        "NOWHERE.md",
        "link (METHOD.md#no-such-part)",
        'docs/METHOD.md, "No such part"',
    ]


def test_every_name_and_path_in_the_docs_exists():
    stale = [
        f"{path.relative_to(ROOT).as_posix()}:{number}: {what} ({why})"
        for path in DOCS
        for number, what, why in references(path)
    ]
    assert not stale, "stale references in the docs:\n" + "\n".join(stale)
