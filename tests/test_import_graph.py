"""Import structure (issue 12): gnss is the ground floor (imports nothing from gmis), no
import circle between modules, and the packages are layered gnss ← gmis engine ← vce,
calibration ← the command layer (gmis.cli, gmis.batch). The graph comes from the source
(tests/import_graph.py; `python tests/import_graph.py` prints it)."""

from tests.import_graph import (
    COMMAND_MODULES,
    cross_edges,
    cycles,
    import_graph,
    package_graph,
    without_modules,
)


def test_graph_sees_known_edges_and_cycles():
    g = import_graph()
    assert "gmis.tc_epochs" in g["gmis.tc_filter"]
    assert "gnss.geodesy" in g["gmis.earth"]
    assert "calibration.job" in g["gmis.cli"]          # through the CLI's _import("...")
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_gnss_imports_nothing_from_gmis():
    assert cross_edges(import_graph(), "gnss", "gmis") == []


def test_no_import_cycle_between_modules():
    """Function-level imports included: no module reaches itself."""
    assert cycles(import_graph()) == []


def test_packages_are_layered():
    """Without the command layer the package graph has no circle (gnss ← gmis ← vce,
    calibration), and only the command modules import vce or calibration from gmis."""
    g = import_graph()
    engine = without_modules(g, COMMAND_MODULES)
    assert cycles(package_graph(engine)) == []
    assert package_graph(engine)["gmis"] == {"gnss"}
    upward = {a for pkg in ("vce", "calibration") for a, _ in cross_edges(g, "gmis", pkg)}
    assert upward <= set(COMMAND_MODULES), upward


def test_no_package_circle_at_import_time():
    packages = package_graph(import_graph(top_level_only=True))
    assert "gmis" not in packages.get("gnss", set())
    assert cycles(packages) == []
