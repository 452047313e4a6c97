"""The second embedded rule on a grid of pixels (:func:`pmdsim.render.convergence_grid.
convergence_stride`): it enters only the medians of the observed convergence, so on a large
camera it is rendered at every 2nd or 4th row and column. Checked against the same render
with the pass on every pixel: the grid pixels' inputs of the convergence are the same
numbers, the others are left out, the factor is the median over the grid, and nothing
else changes; the tile path and the whole-camera path give the same bytes."""

from __future__ import annotations

import numpy as np
import pytest

from pmdsim.config import parse_config
from pmdsim.kernels import bundle as kb
from pmdsim.render import Simulation
from pmdsim.render import results as results_mod
from pmdsim.render import convergence_grid as rows
from pmdsim.render import simulation as simulation_mod
from pmdsim.scene.sampling import ConeSampling
from test_quadrature import fig3

WIDTHS = (50.0, 400.0, 3200.0)


def _config():
    d = fig3(n_rays=256, mode="rule")
    d["brdf"]["alpha_y"] = 0.003  # unequal alphas
    d["camera"]["position_mm"] = [-845.2, 420.0, 1812.6]  # off the x-z plane
    return parse_config(d)


def _render(cfg, monkeypatch, grid_pixels: int, fused: bool = True):
    """The fringes of the 40 x 32 camera (tiles of 5 rows: they do not divide the grid's
    step), with ``CONVERGENCE_GRID_PIXELS = grid_pixels``, and the (ratio, rel) arrays
    the convergence was computed from."""
    seen = []
    original = results_mod.convergence_of_ratios

    def spy(ratio, rel, k):
        seen.append((ratio.copy(), rel.copy()))
        return original(ratio, rel, k)

    with monkeypatch.context() as mp:
        mp.setattr(rows, "CONVERGENCE_GRID_PIXELS", grid_pixels)
        mp.setattr(simulation_mod, "convergence_of_ratios", spy)
        # the embedded rules' path (Fig. 3's fringes take the pilot's: this one remains for
        # a rule on a non-smooth integrand below 2 x replicates nodes)
        mp.setattr(simulation_mod.Simulation, "pilot_applies", lambda self: False)
        if not fused:
            mp.setattr(simulation_mod, "fuses", lambda *args: False)
        sim = Simulation.from_config(cfg)
        sim.tile_rows, sim.num_workers = 5, 2
        fr = sim.render_fringes(WIDTHS, ["x", "y"], 4)
    assert len(seen) == 1
    return fr, seen[0]


@pytest.mark.parametrize("fused", [True, False])
def test_the_second_embedded_rule_on_a_grid_changes_only_the_convergence(fused, monkeypatch):
    cfg = _config()
    full, (ratio1, rel1) = _render(cfg, monkeypatch, 10**9, fused)  # every pixel
    grid, (ratio4, rel4) = _render(cfg, monkeypatch, 40 * 32 // 16, fused)  # every 4th
    nd, nw = 2, len(WIDTHS)
    r1, r4 = ratio1.reshape(nd, nw, 32, 40), ratio4.reshape(nd, nw, 32, 40)
    on = np.zeros((32, 40), bool)
    on[::4, ::4] = True
    assert np.isfinite(r1[..., on]).sum() >= 30 * nd * nw  # most grid pixels see the plate
    # the grid's pixels: the same numbers; the others: left out of the medians
    assert np.array_equal(r4[..., on], r1[..., on], equal_nan=True)
    assert not np.isfinite(r4[..., ~on]).any()
    assert np.array_equal(rel4, rel1, equal_nan=True)
    # the factor: the median over the grid's pixels of the full render's inputs
    expect = results_mod.convergence_of_ratios(
        np.ascontiguousarray(r1[..., on]),
        np.ascontiguousarray(rel1.reshape(nd, nw, 32, 40)[..., on]), _exponent(full))
    assert np.array_equal(grid.convergence, expect)
    assert not np.array_equal(grid.convergence, full.convergence)  # a grid of 80 pixels
    # nothing else: the rule's sums, images, energies and the embedded rule's error
    for name in ("images", "sums", "f_total", "f_hit", "sums_err"):
        a, b = getattr(grid, name), getattr(full, name)
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), name


def _exponent(fr):
    from pmdsim.scene.quadrature import convergence_exponent

    return convergence_exponent(tuple(fr.sampling["order"]), fr.sampling["kind"])


def test_tiles_and_the_whole_camera_loop_give_the_same_bytes_on_a_grid(monkeypatch):
    cfg = _config()
    fused, _ = _render(cfg, monkeypatch, 40 * 32 // 4, True)  # every 2nd pixel
    apart, _ = _render(cfg, monkeypatch, 40 * 32 // 4, False)
    for name in ("images", "sums", "f_total", "f_hit", "sums_err", "convergence"):
        a, b = getattr(fused, name), getattr(apart, name)
        assert np.array_equal(a, b, equal_nan=True), name
    assert np.array_equal(fused.phase_error(), apart.phase_error(), equal_nan=True)


def test_the_grid_step_and_which_pixels_it_keeps():
    class Cam:
        is_simple_pinhole = True
        width, height = 1280, 1024

    rule = ConeSampling(n_rays=256, mode="rule")
    second = rule.error_passes()[2]
    assert [rows.convergence_stride(p, Cam) for p in rule.error_passes()] == [1, 1, 4]
    Cam.width, Cam.height = 1024, 1000  # 1,024,000 < 16 x 65536 pixels: every 2nd
    assert rows.convergence_stride(second, Cam) == 2
    Cam.width, Cam.height = 320, 256  # 81,920 < 4 x 65536 pixels: every pixel
    assert rows.convergence_stride(second, Cam) == 1
    Cam.width, Cam.height, Cam.is_simple_pinhole = 1280, 1024, False  # sub-rays: every pixel
    assert rows.convergence_stride(second, Cam) == 1
    Cam.is_simple_pinhole = True
    assert rows.convergence_stride(ConeSampling(n_rays=64, mode="rqmc").error_passes()[2], Cam) == 1
    # camera rows 5..11 of a 7 px wide camera, step 3: global rows 6 and 9, columns 0, 3, 6
    geo = np.ones((7 * 7, kb.G_SIZE))
    rows.keep_grid(geo, 5, 12, 7, 3)
    kept = geo[:, kb.G_VALID].reshape(7, 7) == 1.0
    want = np.zeros((7, 7), bool)
    want[[1, 4], :] = True
    want &= (np.arange(7) % 3 == 0)[None, :]
    assert np.array_equal(kept, want)
    assert (geo[:, : kb.G_VALID] == 1.0).all()  # nothing else touched
    assert rows.grid_share(np.ones((8, 8), bool), 4) == pytest.approx(4 / 64)
