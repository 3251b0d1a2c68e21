"""Which smoother a run uses: the CLI's --smooth flag over the recipe's [filter].smoother.

Kept apart from gmis.smoothed_run so that a forward run decides without importing the
smoother (and scipy.linalg)."""

from __future__ import annotations

from gmis.errors import GmisInputError


def smoother_choice(recipe, smooth: bool | None) -> str:
    """"none" or "two_filter": the --smooth flag (True) over [filter].smoother; a tightly
    coupled recipe with --smooth is refused (its ambiguity states are not smoothed)."""
    choice = "two_filter" if smooth else recipe.filter.smoother
    if choice != "none" and recipe.filter.mode == "tight":
        raise GmisInputError("--smooth: the smoother does not handle the ambiguity states of "
                             "[filter].mode = \"tight\"; run without --smooth",
                             source=str(recipe.path))
    return choice
