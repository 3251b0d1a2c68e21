"""The module import graph of the repository's packages, from the source (ast), and its
cycles. Run as a script to print the graph's size, every cycle and the gnss → gmis edges:

    python tests/import_graph.py

An edge a → b means module a imports module b (or a name from it) anywhere in its source,
or calls ``importlib.import_module("b")`` / the CLI's ``_import("b", ...)`` with a constant;
``top_level_only`` keeps the imports executed at import time (module body, not inside a
function), the ones that can make an import-time circle.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("gmis", "gnss", "vce", "calibration")
# calls that import a module named by a string constant (the CLI imports each command's
# module so that a command missing from a version exits 3): they are edges too
IMPORT_CALLS = ("_import", "import_module")
# the command layer: the only gmis modules allowed to import the packages built on the
# engine (vce, calibration), to dispatch `gmis vce`, `gmis calibrate` and batch jobs
COMMAND_MODULES = ("gmis.cli", "gmis.batch", "gmis.__main__")


def module_name(path: Path, root: Path = REPO) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _resolve(name: str, modules: set) -> str | None:
    """The longest prefix of a dotted name that is one of our modules."""
    while name:
        if name in modules:
            return name
        name = name.rpartition(".")[0]
    return None


def import_graph(root: Path = REPO, packages=PACKAGES, top_level_only: bool = False) -> dict:
    """{module: set of imported modules of the packages} for every .py file below them."""
    files = [p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))]
    modules = {module_name(p, root) for p in files}
    graph = {}
    for path in files:
        me = module_name(path, root)
        package = me if path.name == "__init__.py" else me.rpartition(".")[0]
        tree = ast.parse(path.read_text(), str(path))
        nodes = tree.body if top_level_only else ast.walk(tree)
        edges = set()
        for node in nodes:
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([base] if base else []))
                targets = [f"{base}.{a.name}" for a in node.names] + [base]
            elif (isinstance(node, ast.Call) and node.args
                  and isinstance(node.args[0], ast.Constant)
                  and isinstance(node.args[0].value, str)
                  and getattr(node.func, "id", getattr(node.func, "attr", None))
                  in IMPORT_CALLS):
                targets = [node.args[0].value]
            for t in targets:
                hit = _resolve(t, modules)
                if hit and hit != me:
                    edges.add(hit)
                    break
        graph[me] = edges
    return graph


def cycles(graph: dict) -> list:
    """The strongly connected components with more than one module (Tarjan), sorted."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    counter = [0]

    def visit(v):
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
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(max(10_000, sys.getrecursionlimit()))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def cross_edges(graph: dict, src_pkg: str, dst_pkg: str) -> list:
    """(a, b) edges from modules of package src_pkg to modules of dst_pkg."""
    return sorted((a, b) for a, bs in graph.items() for b in bs
                  if a.split(".")[0] == src_pkg and b.split(".")[0] == dst_pkg)


def without_modules(graph: dict, names) -> dict:
    """The graph with the modules ``names`` (and every edge to them) removed."""
    return {a: {b for b in bs if b not in names} for a, bs in graph.items() if a not in names}


def package_graph(graph: dict) -> dict:
    """{package: set of other packages it imports} from a module graph."""
    out = {}
    for a, bs in graph.items():
        for b in bs:
            pa, pb = a.split(".")[0], b.split(".")[0]
            if pa != pb:
                out.setdefault(pa, set()).add(pb)
    return out


if __name__ == "__main__":
    for top in (True, False):
        g = import_graph(top_level_only=top)
        what = "import-time (module body)" if top else "all (incl. function-level)"
        print(f"{what}: {len(g)} modules, {sum(map(len, g.values()))} edges")
        for c in cycles(g):
            print("  cycle:", " ⇄ ".join(c))
        print("  gnss → gmis edges:", cross_edges(g, "gnss", "gmis") or "none")
        print("  packages:", {k: sorted(v) for k, v in sorted(package_graph(g).items())},
              "cycles:", cycles(package_graph(g)) or "none")
        engine = without_modules(g, COMMAND_MODULES)
        print("  packages without the command layer", COMMAND_MODULES, ":",
              {k: sorted(v) for k, v in sorted(package_graph(engine).items())},
              "cycles:", cycles(package_graph(engine)) or "none")
