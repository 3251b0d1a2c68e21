"""[noise].gnss_position_scale / gnss_velocity_scale / heading_scale multiply the streams'
per-epoch σ when they are read, and `gmis vce` writes its aiding scales there, so a tuned
fragment used as [paths].noise_override reproduces the σ the last VCE iteration used."""

import numpy as np
import pytest

from gmis.errors import GmisInputError
from gmis.noise_registry import apply_aiding_scales
from gmis.readers import load_dataset
from gmis.recipe import format_noise_fragment, load_recipe


def test_scales_multiply_the_per_epoch_sigmas(dataset):
    plain = load_dataset(load_recipe(dataset.write()))
    doc = dataset.modified("noise", gnss_position_scale=1.3, gnss_velocity_scale=0.5,
                           heading_scale=2.0)
    scaled = load_dataset(load_recipe(dataset.write(doc)))
    np.testing.assert_allclose(scaled.gnss.pos_sigma, 1.3 * plain.gnss.pos_sigma, rtol=1e-15)
    if plain.gnss.vel_sigma is not None:
        np.testing.assert_allclose(scaled.gnss.vel_sigma, 0.5 * plain.gnss.vel_sigma,
                                   rtol=1e-15)
    if plain.heading is not None:
        np.testing.assert_allclose(scaled.heading.sigma, 2.0 * plain.heading.sigma,
                                   rtol=1e-15)


def test_vce_scales_compose_with_the_recipes_and_round_trip(dataset, tmp_path):
    recipe = load_recipe(dataset.write(dataset.modified("noise", gnss_position_scale=2.0)))
    tuned = apply_aiding_scales(recipe.noise, {"gnss_position": 1.25, "heading": 0.8})
    assert tuned.gnss_position_sigma_scale == pytest.approx(2.5)
    assert tuned.heading_sigma_scale == pytest.approx(0.8)
    assert tuned.gnss_velocity_sigma_scale == 1.0
    assert tuned.gnss_position_sigma_m == recipe.noise.gnss_position_sigma_m  # not twice
    frag = tmp_path / "tuned_noise.toml"
    frag.write_text(format_noise_fragment(tuned, "test"))
    back = load_recipe(dataset.write(dataset.modified("paths", noise_override=str(frag))))
    assert back.noise.gnss_position_sigma_scale == pytest.approx(2.5)


def test_scale_must_be_positive(dataset):
    with pytest.raises(GmisInputError, match="noise.gnss_position_scale"):
        load_recipe(dataset.write(dataset.modified("noise", gnss_position_scale=0.0)))
