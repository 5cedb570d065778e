"""The layering docs/architecture.md draws, held by a test: no import cycle between the
package's modules (at import time or inside functions), no module using another one's
`_private` name and none over 600 lines — the figures `benchmarks/house.py` prints."""

import importlib.util
from pathlib import Path

HOUSE = Path(__file__).resolve().parents[1] / "benchmarks" / "house.py"


def test_no_import_cycle_and_no_private_name_across_modules():
    spec = importlib.util.spec_from_file_location("house", HOUSE)
    house = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(house)
    files, graph, eager, pkg_uses, _ = house.analyse()
    # importing hrgjax.ins.alignment runs hrgjax/ins/__init__.py: both are edges (a cycle
    # through a package's __init__ went unseen: plots -> calibration -> session -> plots)
    modules = {house.module_name(p) for p in files}
    assert house._edges("hrgjax.units", {"hrgjax.ins.alignment"}, modules) == {
        "hrgjax.ins", "hrgjax.ins.alignment"}  # fmt: skip
    assert "hrgjax.calibration" not in house._edges("hrgjax.calibration.reduce",
                                                    {"hrgjax.units"}, modules)  # fmt: skip
    assert house.cycles(eager) == [], house.cycles(eager)
    assert house.cycles(graph) == [], house.cycles(graph)
    assert pkg_uses == {}, pkg_uses
    long = {str(p): n for p in files if (n := len(p.read_text().splitlines())) > 600}
    assert not long, long


def test_no_control_character_in_the_sources():
    """A tab or form feed in a source file is a LaTeX escape (`\\top`, `\\theta`, `\\frac`)
    that a docstring without the `r` prefix turned into a control character: the rendered
    API page then shows "^ op" for "^⊤"."""
    root = HOUSE.parents[1]
    bad = {
        str(p.relative_to(root)): i
        for folder in ("hrgjax", "benchmarks", "tests", "docs")
        for p in sorted((root / folder).rglob("*"))
        if p.suffix in (".py", ".md")
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if any(c in line for c in "\t\x07\x08\x0b\x0c")
    }
    assert not bad, bad


def test_marks_sit_on_tests():
    """A `@pytest.mark.…` on a helper is dropped silently by pytest: a slow test whose
    decorator a refactor left above a new helper ran in the fast tier (20 physical fits,
    ≈ 40 s of `make test`) while the helper carried the mark."""
    import ast

    root = HOUSE.parents[1] / "tests"
    stray = []
    for p in sorted(root.glob("*.py")):
        for node in ast.walk(ast.parse(p.read_text())):
            if not isinstance(node, ast.FunctionDef | ast.ClassDef) or node.name.startswith(
                ("test_", "Test")
            ):
                continue
            for dec in node.decorator_list:
                target = dec.func if isinstance(dec, ast.Call) else dec
                if "mark" in ast.unparse(target).split("."):
                    stray.append(f"{p.name}:{node.lineno} {node.name}")
    assert not stray, stray
