"""Functions stay short (issues 26 and 69): a library function's code (its definition without
its docstring) is at most 60 lines, and with its docstring at most 80 (one screen); a longer one
is split into well-named steps. An exemption from the first bound would be named here, capped at
its length then, so the list can only shrink; today there is none, and the second bound has none.

``python tests/test_function_length.py [N]`` lists the library's functions over N lines (default
40), longest first, with their code lines and their lines with the docstring.
"""

import ast
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
LIBRARY = ("furuta_gym", "models", "controllers")
MAX_LINES = 60
MAX_LINES_WITH_DOCSTRING = 80
# Functions allowed over MAX_LINES, by "path:qualified name", each with the most lines it may
# have (its length when it was exempted) and why it is not split yet.
EXEMPT: dict[str, int] = {}


def _code_lines(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Lines from ``def`` (decorators excluded) to the function's end, less its docstring's."""
    lines = (fn.end_lineno or fn.lineno) - fn.lineno + 1
    first = fn.body[0]
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        lines -= (first.end_lineno or first.lineno) - first.lineno + 1
    return lines


def function_lengths() -> dict[str, tuple[int, int]]:
    """``{"path:qualified name": (code lines, lines with the docstring)}`` of every library
    function and method, nested ones included (their lines count in their parent too)."""
    lengths = {}

    def walk(node: ast.AST, path: str, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                whole = (child.end_lineno or child.lineno) - child.lineno + 1
                lengths[f"{path}:{prefix}{child.name}"] = (_code_lines(child), whole)
                walk(child, path, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                walk(child, path, f"{prefix}{child.name}.")

    for folder in LIBRARY:
        for file in sorted((REPO / folder).rglob("*.py")):
            if "__pycache__" not in file.parts:
                walk(ast.parse(file.read_text()), file.relative_to(REPO).as_posix(), "")
    return lengths


def _too_long(lengths: dict[str, tuple[int, int]], exempt: dict[str, int] = EXEMPT) -> list[str]:
    """Functions over their bound (MAX_LINES, or an exemption's cap), with their code lines."""
    return [
        f"{name}: {code} lines of code (at most {exempt.get(name, MAX_LINES)})"
        for name, (code, _) in sorted(lengths.items())
        if code > exempt.get(name, MAX_LINES)
    ]


def test_no_library_function_is_over_its_bound():
    lengths = function_lengths()
    assert len(lengths) > 1000  # the walk found the library
    long = _too_long(lengths)
    assert not long, "split these into well-named steps:\n" + "\n".join(long)


def test_no_library_function_is_over_a_screen_with_its_docstring():
    long = [
        f"{name}: {whole} lines"
        for name, (_, whole) in sorted(function_lengths().items())
        if whole > MAX_LINES_WITH_DOCSTRING
    ]
    assert not long, f"over {MAX_LINES_WITH_DOCSTRING} lines; split these into well-named steps:\n" + "\n".join(long)


def test_every_exemption_names_a_function_that_still_needs_it():
    # an exemption outlives its reason silently otherwise: a function split below the bound, or
    # renamed, must leave the list
    lengths = function_lengths()
    stale = sorted(name for name in EXEMPT if lengths.get(name, (0, 0))[0] <= MAX_LINES)
    assert not stale, "exempt but within the bound (remove from the list): " + ", ".join(stale)


def test_the_bound_counts_code_not_docstrings():
    source = 'def f():\n    """Doc\n\n    more doc.\n    """\n    a = 1\n    return a\n'
    fn = ast.parse(source).body[0]
    assert isinstance(fn, ast.FunctionDef) and _code_lines(fn) == 3
    long = {"furuta_gym/x.py:new": (MAX_LINES + 1, 90), "furuta_gym/old.py:capped": (67, 80)}
    assert _too_long(long, {"furuta_gym/old.py:capped": 66}) == [
        "furuta_gym/old.py:capped: 67 lines of code (at most 66)",
        f"furuta_gym/x.py:new: {MAX_LINES + 1} lines of code (at most {MAX_LINES})",
    ]


if __name__ == "__main__":
    over = int(sys.argv[1]) if len(sys.argv) > 1 else 40
    rows = sorted(((code, whole, name) for name, (code, whole) in function_lengths().items()), reverse=True)
    for code, whole, name in rows:
        if code > over or whole > over:
            print(f"{code:4d} {whole:4d}  {name}")
    for bound in (60, 80):
        print(
            f"over {bound}: {sum(c > bound for c, _, _ in rows)} by code, {sum(w > bound for _, w, _ in rows)} with docstrings"
        )
