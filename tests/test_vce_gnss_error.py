"""VCE of the time-correlated fix error (gmis.gnss_error_states, vce.components
gnss_error_components): the Gauss-Markov driving noise is a process-noise variance
component, so a consumer receiver's fix-error σ_b is estimated next to the white part.
Simulated truth (gmis.simulate.consumer_receiver, the scenario of test_consumer_receiver):
σ_b 1.5 m per axis, τ 5 s, white 0.1 / 0.1 / 0.2 m; τ is the recipe's (not a linear
component), σ_b starts at 3× the truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tests.test_consumer_receiver import MODEL, simulate_receiver_drives
from vce.components import GNSS_ERROR_COMPONENTS


@pytest.fixture(scope="module")
def tuned(tmp_path_factory):
    """The VCE job on each seed of test_consumer_receiver's drives (4, 5, 6)."""
    from gmis.recipe import GnssSection, load_recipe
    from vce.tune import tune

    out = []
    for sim, _ in simulate_receiver_drives(tmp_path_factory.mktemp("vce-gnss-error")):
        recipe = load_recipe(sim.recipe_path)
        recipe = replace(recipe, gnss=replace(
            GnssSection(), time_offset_s=-MODEL.latency_s,
            error_correlation_time_s=MODEL.error_tau_s,
            error_sigma_m=tuple(3.0 * s for s in MODEL.error_sigma_m)))
        out.append(tune(recipe, max_iterations=10))
    return out


def test_fix_error_sigma_is_recovered_from_a_3x_start(tuned):
    ratios = []
    for res in tuned:
        names = [c.name for c in res.components]
        assert res.converged
        last = res.history[-1]
        for axis, name in enumerate(GNSS_ERROR_COMPONENTS):
            j = names.index(name)
            assert last.estimator[j] != "held", (name, last.status[j])
            assert 0.0 < last.sigma0_sd[j] < 0.15          # determined by the data
            ratio = res.final_sigma[j] / MODEL.error_sigma_m[axis]
            assert abs(ratio - 1.0) < 0.2, (name, ratio)
            ratios.append(ratio ** 2)
        # the white part is the file's σ (truth 1); it is poorly determined next to a
        # 1.5-m correlated error and said so (simplified estimator, precision > 0.1)
        j = names.index("gnss_position")
        assert abs(res.final_sigma[j] - 1.0) < 3.0 * last.sigma0_sd[j]
    # variance ratio over 3 seeds × 3 axes: within 3 s.e. of the single-run precision ~0.1
    assert abs(np.mean(ratios) - 1.0) < 0.1, ratios


def test_fix_error_noise_is_seen_only_at_position_updates(tuned):
    """The driving noise accumulated between position updates enters each position update
    as one pseudo-observation: its residuals exist at (and only at) those epochs."""
    res = tuned[0]
    rec = res.records_final
    from gmis.gmikf import SLOT_POS

    k = [c.name for c in res.components].index(GNSS_ERROR_COMPONENTS[0])
    idx = res.components[k].index[0]
    has_rw = np.isfinite(rec.rw[:, idx]) & (rec.rw[:, idx] > 0)
    pos_used = np.isfinite(rec.rz[:, SLOT_POS])
    assert has_rw.sum() > 250
    assert not (has_rw & ~pos_used).any()
