"""The house's figures (issue 45): module sizes, import cycles, private names crossing modules.

Printed: the largest modules of `hrgjax/` (lines), the import cycles between its modules
(module-level imports and imports inside functions alike), and every use of another module's
`_private` name — `from m import _x`, `import m as _m; _m._x`, `m._x` — in the package and in
`tests/`. A name is private when it starts with one underscore; a module's own names, dunder
names and private *modules* imported whole (`from . import _compiled`) are not counted, but
private names reached through them are (`_compiled._top_level`).

Usage: `.venv/bin/python benchmarks/house.py [--list]` (`--list`: every private use, by file).
"""

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "hrgjax"


def module_name(path):
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def resolve(current, is_pkg, level, target):
    """Absolute module name of a (possibly relative) import."""
    if level == 0:
        return target
    base = current.split(".")
    base = base if is_pkg else base[:-1]
    base = base[: len(base) - (level - 1)] if level > 1 else base
    return ".".join(base + ([target] if target else []))


def private(name):
    return name.startswith("_") and not name.startswith("__")


def top_level(tree):
    """The module body's statements, `if`/`try` blocks included (not functions, classes)."""
    todo, out = list(tree.body), []
    while todo:
        node = todo.pop()
        out.append(node)
        if isinstance(node, (ast.If, ast.Try)):
            todo += node.body + node.orelse + getattr(node, "finalbody", [])
            todo += [s for h in getattr(node, "handlers", []) for s in h.body]
    return out


def scan(path, modules, module_level=False):
    """(imports, private uses) of one file; `module_level`: imports at import time only."""
    name = module_name(path) if path.is_relative_to(PKG) else path.stem
    is_pkg = path.name == "__init__.py"
    tree = ast.parse(path.read_text())
    imports, uses, aliases = set(), [], {}
    for node in top_level(tree) if module_level else ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            src = resolve(name, is_pkg, node.level, node.module or "")
            for a in node.names:
                full = f"{src}.{a.name}"
                if full in modules:  # a module imported whole
                    imports.add(full)
                    aliases[a.asname or a.name] = full
                else:
                    imports.add(src)
                    if private(a.name) and src.startswith("hrgjax") and src != name:
                        uses.append((node.lineno, f"{src}.{a.name}"))
        elif isinstance(node, ast.Import):
            for a in node.names:
                imports.add(a.name)
                if a.asname:
                    aliases[a.asname] = a.name
                else:
                    aliases[a.name.split(".")[0]] = a.name.split(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and private(node.attr):
            chain, v = [node.attr], node.value
            while isinstance(v, ast.Attribute):
                chain.append(v.attr)
                v = v.value
            if isinstance(v, ast.Name) and v.id in aliases:
                mod = ".".join([aliases[v.id]] + chain[:0:-1])
                if mod.startswith("hrgjax") and mod in modules and mod != name:
                    uses.append((node.lineno, f"{mod}.{node.attr}"))
    return name, {i for i in imports if i.startswith("hrgjax")}, uses


def cycles(graph):
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    sys.setrecursionlimit(10000)

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
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

    for v in list(graph):
        if v not in index:
            visit(v)
    return out


def _edges(name, imports, modules):
    """The modules `name`'s imports run: each imported module and every package on its path
    (importing `hrgjax.ins.x` runs `hrgjax/ins/__init__.py`), but not `name`'s own packages
    (a module's package is being imported already when it runs)."""
    own = {".".join(name.split(".")[:k]) for k in range(1, name.count(".") + 1)}
    out = set()
    for i in imports:
        parts = i.split(".")
        for k in range(2, len(parts) + 1):
            q = ".".join(parts[:k])
            if q in modules and q != name and q not in own:
                out.add(q)
    return out


def analyse():
    """`(files, graph, eager, pkg_uses, test_uses)`: the package's modules, their imports
    (all, and at import time only) and the uses of another module's `_private` name in the
    package and in the tests."""
    files = sorted(PKG.rglob("*.py"))
    modules = {module_name(p) for p in files}
    graph, eager, pkg_uses, test_uses = {}, {}, {}, {}
    for p in files:
        name, imports, uses = scan(p, modules)
        graph[name] = _edges(name, imports, modules)
        eager[name] = _edges(name, scan(p, modules, module_level=True)[1], modules)
        if uses:
            pkg_uses[str(p.relative_to(ROOT))] = uses
    for p in sorted((ROOT / "tests").glob("*.py")):
        _, _, uses = scan(p, modules)
        if uses:
            test_uses[str(p.relative_to(ROOT))] = uses
    return files, graph, eager, pkg_uses, test_uses


def main():
    files, graph, eager, pkg_uses, test_uses = analyse()
    sizes = sorted(((len(p.read_text().splitlines()), str(p.relative_to(ROOT))) for p in files),
                   reverse=True)  # fmt: skip
    print("largest modules (lines):")
    for n, p in sizes[:8]:
        print(f"  {n:5d}  {p}")
    for title, g in (("at import time", eager), ("counting imports inside functions", graph)):
        found = cycles(g)
        print(f"import cycles {title}: {len(found)}")
        for c in found:
            print("  " + " <-> ".join(c))
    upstream = []
    for p in files:
        for i, line in enumerate(p.read_text().splitlines(), 1):
            if any(k in line for k in ("jax._src", "equinox._", "._value", "diffrax._",
                                       "optimistix._", "lineax._")):  # fmt: skip
                upstream.append(f"{p.relative_to(ROOT)}:{i}  {line.strip()[:90]}")
    print(f"lines reaching upstream private internals: {len(upstream)}")
    for u in upstream:
        print("  " + u)
    n_pkg = sum(len(u) for u in pkg_uses.values())
    n_test = sum(len(u) for u in test_uses.values())
    distinct = lambda d: len({u for us in d.values() for _, u in us})  # noqa: E731
    print(f"private names used across modules: package {n_pkg} uses ({distinct(pkg_uses)} names), "
          f"tests {n_test} uses ({distinct(test_uses)} names)")  # fmt: skip
    if "--list" in sys.argv:
        for title, d in (("package", pkg_uses), ("tests", test_uses)):
            print(f"{title}:")
            for f, us in d.items():
                for line, u in us:
                    print(f"  {f}:{line}  {u}")


if __name__ == "__main__":
    main()
