"""The package's shape: imports flow one way (no cycle), and code cites papers by reference key
(docs/references.md), not by internal labels. Module size is not a rule here (one concept per
module; a large module is a smell to discuss in review)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "ivobs"
ROOT = SRC.parents[1]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(SRC.rglob("*.py"))}


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports(name: str, path: Path) -> set[str]:
    """The ivobs modules that ``name`` imports anywhere (functions included), except under
    ``if TYPE_CHECKING:`` (annotations only, never executed)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.add(target)
            found.update(f"{target}.{a.name}" for a in node.names)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return {m for m in found if m in MODULES and m != name and m != "ivobs"}


def _cycles() -> list[list[str]]:
    graph = {name: _imports(name, path) for name, path in MODULES.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def strong(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            strong(v)
    return out


def test_no_import_cycle() -> None:
    assert _cycles() == []


_LABELS = re.compile(
    r"\b(?:seeds?/|seed 00\d|paper 00\d|papers? 00\d|00[1-4] (?:eq|Theorem|Remark|Prop|Section|"
    r"Algorithm|Alg|Lemma|Fig|§)|\(00[1-4]\))|\b[Aa]udit\b|\b[AE]\d{1,2}b?(?::\s[a-z]|-style| only)"
    r"|(?<![\w.])\((?:[AE]\d{1,2}b?(?:, )?)+\)|\btest_[ae]\d{1,2}_|\bpaper00\d"
)


def _text_files() -> list[Path]:
    files = [p for p in SRC.rglob("*.py")]
    files += [p for p in (ROOT / "tests").glob("*.py") if p.name != "test_architecture.py"]
    files += [*(ROOT / "docs").rglob("*.md"), ROOT / "README.md"]
    return files


def test_papers_are_cited_by_reference_key() -> None:
    """Docstrings and docs cite ``[Tang2019, eq. (34)]``, not numbered seed files or audit items."""
    hits = []
    for path in _text_files():
        for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if _LABELS.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()[:90]}")
    assert hits == [], f"{len(hits)} lines cite labels, first: {hits[:15]}"
