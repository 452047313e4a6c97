"""Every variant of the bundle kernels against their stored outputs.

``tests/kernel_cases.py`` lists one case per BRDF model (Ward's three normalisations,
Beckmann with and without Smith shadowing, the mirror, the slope table, the grating
orders), kernel (cone, lobe) and phase-2 mode (tables, harmonic with powers, images,
dots, transport), plus the display correction and per-pixel parameters;
``tests/data/kernel_outputs.npz`` holds what the kernels computed for them before
per-ray weights were added. With all weights 1
every output must agree to 1e-12 of its column's largest magnitude (measured on the
machine that wrote the file: bit for bit), with NaN in the same places. The physics of
each variant is tested against independent references elsewhere (test_kernels,
test_radiometric, test_slope_density, test_display, test_brdf_variation).
"""

from __future__ import annotations

import numpy as np
import pytest

from kernel_cases import DATA, cases, run_case

CASES = dict(cases())


@pytest.fixture(scope="module")
def stored():
    with np.load(DATA) as data:
        return {k: data[k] for k in data.files}


def _compare(got, ref, what):
    assert got.shape == ref.shape, what
    assert np.array_equal(np.isnan(got), np.isnan(ref)), f"{what}: NaN differ"
    fin = ~np.isnan(ref)
    err = np.where(fin, np.abs(got - ref), 0.0)
    scale = np.max(np.where(fin, np.abs(ref), 0.0), axis=0, keepdims=True)
    assert np.all(err <= 1e-12 * scale), (
        f"{what}: worst |new - old| / column max {np.max(err / np.maximum(scale, 1e-300)):.2e}")


@pytest.mark.parametrize("name", list(CASES))
def test_variant_equals_stored_output(name, stored):
    got = run_case(CASES[name], w_ray="ones")
    assert np.isfinite(got["out"]).any() and np.isnan(got["out"]).any()
    for key, val in got.items():
        _compare(val, stored[f"{name}/{key}"], f"{name} {key}")


def test_every_stored_case_is_run(stored):
    names = {k.split("/")[0] for k in stored}
    assert names == set(CASES)
