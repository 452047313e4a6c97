"""Geometry sanity (:mod:`pmdsim.studies.coverage`): a set-up that sees nothing stops before
rendering with the field to change; a partial view is a warning with its fraction; bundles
hanging off the monitor are flagged."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import make_config
from pmdsim.config import ConfigError
from pmdsim.studies.coverage import check_view, off_monitor_fraction, off_monitor_mask


def _geometry(**changes):
    from pmdsim.render import Simulation

    return Simulation.from_config(make_config(**changes)).geometry()


def test_the_base_scene_sees_surface_and_monitor():
    g = _geometry()
    cov = check_view(g.surface_mask, g.monitor_mask)
    assert 0 < cov.monitor_pixels <= cov.surface_pixels < cov.pixels == 40 * 32
    assert cov.monitor_fraction == pytest.approx((g.surface_mask & g.monitor_mask).mean())


def test_a_camera_looking_away_stops_naming_the_camera():
    g = _geometry(camera={"look_at_mm": [0.0, -2000.0, 0.0]})
    with pytest.raises(ConfigError, match=r"camera\.look_at_mm: the camera sees no surface"):
        check_view(g.surface_mask, g.monitor_mask)


def test_a_monitor_off_the_reflection_stops_naming_the_monitor():
    g = _geometry(monitor={"centre_mm": [0.0, -200.0, 300.0], "look_at_mm": [0.0, 0.0, 0.0]})
    assert g.surface_mask.any()
    with pytest.raises(ConfigError, match=r"monitor\.centre_mm: the surface reflects the camera"):
        check_view(g.surface_mask, g.monitor_mask)


def test_a_partial_view_warns_with_its_fraction_and_a_tiny_one_stops():
    surface = np.zeros((10, 10), bool)
    surface[:, :3] = True
    cov = check_view(surface, surface)
    assert cov.warning is not None and "30 %" in cov.warning
    tiny = np.zeros((100, 100), bool)
    tiny[0, :5] = True  # 0.05 % of the camera
    with pytest.raises(ConfigError, match="diagnostics.min_view_fraction"):
        check_view(tiny, tiny)
    assert check_view(tiny, tiny, min_view_fraction=0.0).monitor_pixels == 5
    assert check_view(np.ones((4, 4), bool), np.ones((4, 4), bool)).warning is None


def test_off_monitor_share_and_flags():
    f_total = np.array([[1.0, 2.0, 0.0, np.nan]])
    f_hit = np.array([[1.0, 1.5, 0.0, np.nan]])
    share = off_monitor_fraction(f_total, f_hit)
    np.testing.assert_allclose(share[0, :3], [0.0, 0.25, 1.0])
    assert np.isnan(share[0, 3])
    surface = np.array([[True, True, True, False]])
    np.testing.assert_array_equal(off_monitor_mask(f_total, f_hit, surface, 0.3),
                                  [[False, False, True, False]])
    np.testing.assert_array_equal(off_monitor_mask(f_total, f_hit, surface, 0.2),
                                  [[False, True, True, False]])


def test_bundles_off_the_monitor_are_flagged_counted_and_never_valid(tmp_path):
    """The monitor moved so that the reflection of part of the plate falls off its edge: the
    pixels whose bundle puts more than max_off_monitor_fraction of its weight off the monitor
    are in ``lobe_off_monitor``, counted in the statistics and not valid; their share, from
    f_hit / f_total of an independent render, exceeds the bound, the others' does not."""
    from pmdsim.render import Simulation
    from pmdsim.run import run_simulation
    from pmdsim.store.schema import load_run

    cfg = make_config(monitor={"centre_mm": [60.0, 85.2, 181.3]},
                      patterns={"fringes": {"widths_px": [25.0, 200.0]}})
    result = run_simulation(cfg, tmp_path / "run", figures=False, diagnostics=False)
    ds = load_run(result.outdir)
    off = ds["lobe_off_monitor"].values
    fr = Simulation.from_config(cfg).render_fringes((25.0,), ("x",), 4)
    surface = ds["surface_mask"].values
    share = 1.0 - fr.f_hit / fr.f_total
    bound = cfg.diagnostics.max_off_monitor_fraction
    assert off.any() and np.all(share[off] > bound)
    assert np.all(share[surface & ~off] <= bound)
    for di, d in enumerate(("x", "y")):
        assert not np.any(ds["valid"].values[di] & off)
        considered = ds["reference_decode_flags"].values[di] == 0
        expected = considered & off & ~ds["low_modulation"].values[di]
        assert result.statistics["directions"][d]["pixels"]["lobe_off_monitor"] == expected.sum()
