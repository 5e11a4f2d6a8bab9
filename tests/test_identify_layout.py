"""identify/ stays walkable: files of one responsibility (≤ 600 lines), no private name
imported from another module, no import circle inside the package."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "motorid"


def _imports(path: Path):
    """(module, name) of every ``from motorid... import name`` in a file, at any depth
    (those under ``if TYPE_CHECKING:`` left out: they name a type, they run nothing)."""
    tree = ast.parse(path.read_text())
    typing_only = {id(n) for node in ast.walk(tree)
                   if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING"
                   for n in ast.walk(node)}
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("motorid"):
            for alias in node.names:
                yield node.module, alias.name


def test_identify_files_are_short():
    long = {p.name: n for p in [*(PACKAGE / "identify").glob("*.py"), PACKAGE / "robust.py"]
            if (n := len(p.read_text().splitlines())) > 600}
    assert not long, long


def test_no_private_name_of_identify_or_robust_is_imported_elsewhere():
    bad = [f"{p.relative_to(PACKAGE.parent)}: {m}.{name}" for p in PACKAGE.rglob("*.py")
           for m, name in _imports(p)
           if m.startswith(("motorid.identify", "motorid.robust")) and name.startswith("_")]
    assert not bad, bad


def test_no_import_circle_inside_identify():
    graph = {p.stem: {m.split(".")[2] for m, _ in _imports(p) if m.startswith("motorid.identify.")}
             for p in (PACKAGE / "identify").glob("*.py")}
    state = {}

    def visit(node, path):
        if state.get(node) == "open":
            raise AssertionError(" -> ".join(path + [node]))
        if state.get(node) != "done":
            state[node] = "open"
            for nxt in sorted(graph.get(node, ())):
                visit(nxt, path + [node])
            state[node] = "done"

    for node in sorted(graph):
        visit(node, [])
