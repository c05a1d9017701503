"""Lines of Python under the given paths: every line, and code lines (no blank, comment or
docstring lines).

    python benchmarks/sloc.py src [--rev REV]      # --rev: the files of a commit (git show)
"""

from __future__ import annotations

import argparse
import ast
import io
import subprocess
import tokenize
from pathlib import Path

SKIP = {
    tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT,
    tokenize.ENDMARKER,
}  # fmt: skip
DOCUMENTED = (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)


def code_lines(src: str) -> int:
    """Lines that hold a token other than a comment, outside docstrings."""
    doc: set[int] = set()
    for node in ast.walk(ast.parse(src)):
        if isinstance(node, DOCUMENTED) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                if isinstance(first.value.value, str):
                    doc.update(range(first.lineno, (first.end_lineno or first.lineno) + 1))
    lines: set[int] = set()
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        if tok.type not in SKIP:
            lines.update(ln for ln in range(tok.start[0], tok.end[0] + 1) if ln not in doc)
    return len(lines)


def sources(path: str, rev: str | None) -> list[str]:
    if rev is None:
        p = Path(path)
        files = sorted(p.rglob("*.py")) if p.is_dir() else [p]
        return [f.read_text(encoding="utf-8") for f in files]
    names = subprocess.run(
        ["git", "ls-tree", "-r", "--name-only", rev, path], capture_output=True, text=True
    ).stdout.split()
    return [
        subprocess.run(["git", "show", f"{rev}:{n}"], capture_output=True, text=True).stdout
        for n in names
        if n.endswith(".py")
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("paths", nargs="+")
    ap.add_argument("--rev", default=None)
    args = ap.parse_args()
    texts = [s for p in args.paths for s in sources(p, args.rev)]
    print(f"lines {sum(s.count(chr(10)) for s in texts)}  code {sum(map(code_lines, texts))}")


if __name__ == "__main__":
    main()
