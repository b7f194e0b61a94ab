"""Benchmark: the layout of ``whiskerid.fit``, measured from its source (issue 45's before/after).

Prints one JSON object: which room (module or sub-package directly below fit) imports which,
the import cycles among fit's modules (strongly connected components of
the import graph grimp builds, deferred imports included), the number of imports inside
functions, the private names imported from another fit module (and from another sub-package of
fit), the module-level function names defined in more than one fit module, the number of modules
and lines, and the 10 longest functions (lines, ``module:qualname``).

Run: ``python benchmarks/fit_layout.py`` (no JAX; a second or two).
"""

import ast
import json
import sys
from collections import defaultdict
from pathlib import Path

import grimp

ROOT = Path(__file__).resolve().parents[1]
FIT = ROOT / "whiskerid" / "fit"
PACKAGE = "whiskerid.fit"


def module_name(path: Path) -> str:
    """The dotted name of a fit source file."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    """The absolute module an ``ImportFrom`` names."""
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    base = base if is_package else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def sub_package(module: str) -> str:
    """The first level below fit a module belongs to (``whiskerid.fit._linear``...)."""
    return ".".join(module.split(".")[:3])


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's components with more than one module (the cycles)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    sys.setrecursionlimit(10_000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found, key=len, reverse=True)


def main() -> None:
    graph = grimp.build_graph("whiskerid", cache_dir=None)
    fit_modules = {m for m in graph.modules if m == PACKAGE or m.startswith(PACKAGE + ".")}
    # A module importing a package it lies in (``from . import x``, ``from .. import y``) is
    # left out: that package's __init__ imports the module back to re-export it, which is
    # how re-exports work, not a cycle between jobs. A package's __init__ importing its own
    # modules stays in, so a cycle through a sibling package's __init__ is found.
    edges = {
        m: {
            w
            for w in graph.find_modules_directly_imported_by(m)
            if w in fit_modules and not m.startswith(w + ".")
        }
        for m in fit_modules
    }
    cycles = strongly_connected(edges)
    # The drawing of the layout: which room (module or sub-package directly below fit) imports
    # which others.
    rooms: dict[str, set[str]] = defaultdict(set)
    for m, targets in edges.items():
        if m == PACKAGE:
            continue
        for w in targets:
            if w != PACKAGE and sub_package(w) != sub_package(m):
                rooms[sub_package(m).rsplit(".", 1)[1]].add(sub_package(w).rsplit(".", 1)[1])

    inner_imports = []
    private_imports = []
    private_across = []
    functions: list[tuple[int, str]] = []
    defined: dict[str, list[str]] = defaultdict(list)
    lines = 0
    files = sorted(FIT.rglob("*.py"))
    for path in files:
        text = path.read_text()
        lines += text.count("\n")
        tree = ast.parse(text)
        module = module_name(path)
        is_package = path.name == "__init__.py"
        for node in tree.body:
            if isinstance(node, ast.FunctionDef):
                defined[node.name].append(module)

        def walk(
            node: ast.AST, qual: str, in_function: bool, module=module, is_package=is_package
        ) -> None:
            for child in ast.iter_child_nodes(node):
                if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                    name = f"{qual}.{child.name}" if qual else child.name
                    if not isinstance(child, ast.ClassDef):
                        length = (child.end_lineno or child.lineno) - child.lineno + 1
                        functions.append((length, f"{module}:{name}"))
                    walk(child, name, in_function or not isinstance(child, ast.ClassDef))
                    continue
                if isinstance(child, ast.Import | ast.ImportFrom) and in_function:
                    inner_imports.append(f"{module}:{qual} line {child.lineno}")
                if isinstance(child, ast.ImportFrom):
                    source = resolve(module, is_package, child)
                    if source.startswith(PACKAGE):
                        for alias in child.names:
                            if alias.name.startswith("_") and alias.name != "__version__":
                                text_ = f"{module} <- {source}.{alias.name}"
                                private_imports.append(text_)
                                if sub_package(source) != sub_package(module):
                                    private_across.append(text_)
                walk(child, qual, in_function)

        walk(tree, "", False)

    functions.sort(key=lambda item: (-item[0], item[1]))
    shared_names = {
        name: sorted(mods) for name, mods in sorted(defined.items()) if len(set(mods)) > 1
    }
    print(
        json.dumps(
            {
                "modules": len(files),
                "lines": lines,
                "cycles": cycles,
                "room_imports": {k: sorted(v) for k, v in sorted(rooms.items())},
                "modules_in_cycles": sum(len(c) for c in cycles),
                "imports_inside_functions": len(inner_imports),
                "imports_inside_functions_at": inner_imports,
                "private_names_imported": len(private_imports),
                "private_names_imported_across_sub_packages": len(private_across),
                "private_names_imported_at": private_imports,
                "module_functions_sharing_a_name": shared_names,
                "longest_functions": [{"lines": n, "function": name} for n, name in functions[:10]],
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
