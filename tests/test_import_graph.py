"""Import structure (issue 12): gnss is the ground floor (imports nothing from gmis), no
import circle between modules. The graph comes from the source (tests/import_graph.py)."""

from tests.import_graph import cross_edges, cycles, import_graph, package_graph

# The read_rtk_recipe / run_rtk_recipe block at the end of gnss/rtk.py (recipe reading and
# the results folder) moves into gmis in the same architecture step (arch-recipe branch);
# until then its two function-level imports are the only gnss → gmis edges allowed.
RECIPE_BLOCK_EDGES = {("gnss.rtk", "gmis.errors"), ("gnss.rtk", "gmis.results")}


def test_graph_sees_known_edges_and_cycles():
    g = import_graph()
    assert "gmis.tc_epochs" in g["gmis.tc_filter"]
    assert "gnss.geodesy" in g["gmis.earth"]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_gnss_imports_nothing_from_gmis():
    assert cross_edges(import_graph(top_level_only=True), "gnss", "gmis") == []
    assert set(cross_edges(import_graph(), "gnss", "gmis")) <= RECIPE_BLOCK_EDGES


def test_no_import_time_cycles():
    assert cycles(import_graph(top_level_only=True)) == []


def test_no_cycles_through_gnss_or_the_tightly_coupled_modules():
    mine = ("gnss.", "gmis.tc", "gmis.earth", "gmis.errors", "gmis.motion",
            "gmis.kalman_update_reference")
    bad = [c for c in cycles(import_graph()) if any(m.startswith(mine) for m in c)]
    assert bad == []


def test_no_package_circle_at_import_time():
    packages = package_graph(import_graph(top_level_only=True))
    assert "gmis" not in packages.get("gnss", set())
    assert cycles(packages) == []
