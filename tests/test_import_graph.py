"""The house stays walkable: dependencies point one way, down the layers, and no packages import each other.

Every module of motorid is parsed (ast, nothing imported) and each of its imports,
at the top or inside a function, is an arrow from its package to the imported
one.  A package sits in one layer of :data:`LAYERS`; an arrow may point to its
own layer or below, never up, and the packages' graph has no circle.

To add a package: put its name in the layer it belongs to (one word in one line).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "motorid"

#: lowest first: physics ← model ← io / bench / identify ← discrepancy ← report ← api ← cli
LAYERS = (
    ("foundation", {"errors", "units", "_atomic", "_jaxconfig", "_cachesize", "_aot", "_version", "robust", "progress"}),
    ("physics", {"physics"}),
    ("model", {"model"}),
    ("edge", {"io", "bench", "identify"}),
    ("analysis", {"discrepancy", "comparators", "experiment_design"}),
    ("report", {"report", "export", "fleet"}),
    ("api", {"api"}),
    ("cli", {"cli", "__main__"}),
)
RANK = {name: rank for rank, (_, names) in enumerate(LAYERS) for name in names}
#: the root package: its version and the lazy attributes of the API (``motorid.fit``, …), imported by anyone
ROOT = "motorid"


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _imports(module: str, path: Path) -> list[tuple[str, int]]:
    """The motorid modules ``module`` imports, with their line numbers."""
    is_package = path.name == "__init__.py"
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: from its package (or from the package itself, for an __init__)
                base = module.split(".")
                base = base[: len(base) - node.level + (1 if is_package else 0)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            for a in node.names:  # `from motorid import model`: the submodule, where there is one
                sub = f"{target}.{a.name}"
                found.append((sub if sub in MODULES else target, node.lineno))
    return [(t, line) for t, line in found if t == ROOT or t.startswith(ROOT + ".")]


def package_of(module: str) -> str:
    """motorid.physics.registry → physics; motorid.model → model; motorid → motorid."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ROOT


def _arrows():
    for module, path in MODULES.items():
        if module == ROOT:
            continue
        for target, line in _imports(module, path):
            src, dst = package_of(module), package_of(target)
            if src != dst and dst != ROOT:
                yield src, dst, f"{path.relative_to(PACKAGE.parent)}:{line} imports {target}"


ARROWS = list(_arrows())


def test_every_package_has_a_layer():
    packages = {package_of(m) for m in MODULES} - {ROOT}
    missing = sorted(p for p in packages if p not in RANK)
    assert not missing, f"add these packages to LAYERS in {Path(__file__).name}: {missing}"


def arrows_up(arrows) -> list:
    """The arrows from a package to one in a higher layer, in words."""
    return [f"{where} ({src}: {LAYERS[RANK[src]][0]} → {dst}: {LAYERS[RANK[dst]][0]})"
            for src, dst, where in arrows if src in RANK and dst in RANK and RANK[dst] > RANK[src]]


def test_no_arrow_points_up():
    up = arrows_up(ARROWS)
    assert not up, "imports that point up the layers:\n" + "\n".join(up)


def _cycle(graph: dict) -> list:
    """One circle of the graph (a list of nodes, first = last), or []."""
    state, stack = {}, []

    def visit(n):
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                return stack[stack.index(m):] + [m]
            if m not in state:
                found = visit(m)
                if found:
                    return found
        stack.pop()
        state[n] = 2
        return []

    for n in sorted(graph):
        if n not in state:
            found = visit(n)
            if found:
                return found
    return []


def test_no_circle_between_packages():
    graph: dict = {}
    for src, dst, _ in ARROWS:
        graph.setdefault(src, set()).add(dst)
    circle = _cycle(graph)
    if circle:
        where = [w for s, d, w in ARROWS if (s, d) in zip(circle, circle[1:])]
        pytest.fail("packages import each other: " + " → ".join(circle) + "\n" + "\n".join(where))


def test_library_never_imports_the_cli():
    bad = [where for src, dst, where in ARROWS if dst in ("cli", "__main__") and src not in ("cli", "__main__")]
    assert not bad, "\n".join(bad)


def test_the_checker_sees_a_circle_and_an_arrow_up():
    """The checker itself: a hand-made circle and an arrow up are found; real arrows are read."""
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert arrows_up([("physics", "model", "x.py:1"), ("model", "physics", "y.py:1")]) == [
        "x.py:1 (physics: physics → model: model)"]
    assert _cycle({"a": {"b"}, "b": set()}) == []
    assert ("discrepancy", "physics") in {(s, d) for s, d, _ in ARROWS}  # select searches the registry
    assert ("bench", "physics") in {(s, d) for s, d, _ in ARROWS}
    assert not any(d == "discrepancy" for s, d, _ in ARROWS if s == "bench")
