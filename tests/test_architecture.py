"""The layering docs/architecture.md draws, held by a test: no import cycle between the
package's modules (at import time or inside functions) and no module using another one's
`_private` name — the figures `benchmarks/house.py` prints."""

import importlib.util
from pathlib import Path

HOUSE = Path(__file__).resolve().parents[1] / "benchmarks" / "house.py"


def test_no_import_cycle_and_no_private_name_across_modules():
    spec = importlib.util.spec_from_file_location("house", HOUSE)
    house = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(house)
    _, graph, eager, pkg_uses, _ = house.analyse()
    assert house.cycles(eager) == [], house.cycles(eager)
    assert house.cycles(graph) == [], house.cycles(graph)
    assert pkg_uses == {}, pkg_uses
