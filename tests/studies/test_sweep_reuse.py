"""Sweeps reuse the vision-ray geometry and the specular reference across points that
share them (keyed by the hash of the configuration sections they depend on), and a reused
one gives the same bytes as one computed afresh."""

from __future__ import annotations

from pmdsim.config import parse_config
from pmdsim.studies import sweep as sw

from test_sweep import _config


def _cfg(**changes):
    d = _config({"parameters": {"brdf.alpha_x": [0.01]}})
    d.pop("sweep")
    for path, value in changes.items():
        node = d
        *head, last = path.split(".")
        for k in head:
            node = node.setdefault(k, {})
        node[last] = value
    return parse_config(d)


def test_keys_follow_the_sections_that_determine_them():
    base = _cfg()
    brdf = _cfg(**{"brdf.alpha_x": 0.03, "brdf.alpha_y": 0.005})
    sampling = _cfg(**{"sampling.n_rays": 32, "sampling.seed": 9})
    widths = _cfg(**{"patterns.fringes.widths_px": [100.0, 400.0, 3200.0]})
    camera = _cfg(**{"camera.position_mm": [-845.2, 0.5, 1812.6]})
    monitor = _cfg(**{"monitor.pixel_pitch_mm": 0.26})
    g, r = sw.geometry_key, sw.reference_key
    for c in (brdf, sampling, widths):  # the geometry is shared
        assert g(c) == g(base)
    for c in (brdf, sampling):  # the reference too, but not across fringe widths
        assert r(c) == r(base)
    assert r(widths) != r(base)
    for c in (camera, monitor):  # a different set-up shares neither
        assert g(c) != g(base) and r(c) != r(base)


def test_a_brdf_change_reuses_a_geometry_change_does_not_and_reuse_changes_no_byte():
    base = _cfg()
    brdf = _cfg(**{"brdf.alpha_x": 0.03, "brdf.alpha_y": 0.005})
    moved = _cfg(**{"camera.position_mm": [-845.2, 3.0, 1812.6]})
    sw.GEOMETRIES.clear()
    sw.REFERENCES.clear()
    sw.measure_point(base, 4)
    reused = sw.measure_point(brdf, 4)
    assert (sw.GEOMETRIES.made, sw.GEOMETRIES.reused) == (1, 1)
    assert (sw.REFERENCES.made, sw.REFERENCES.reused) == (1, 1)
    other = sw.measure_point(moved, 4)
    assert (sw.GEOMETRIES.made, sw.REFERENCES.made) == (2, 2)
    sw.GEOMETRIES.clear()
    sw.REFERENCES.clear()
    fresh = sw.measure_point(brdf, 4)  # computed afresh: the same bytes as reused
    assert sw.GEOMETRIES.made == 1 and sw.GEOMETRIES.reused == 0
    for k in fresh:
        assert fresh[k].tobytes() == reused[k].tobytes(), k
    # the moved camera sees the plate elsewhere: its result is its own
    assert other["phase_deviation"].tobytes() != reused["phase_deviation"].tobytes()


def test_a_sweep_runs_the_points_that_share_a_reference_together(tmp_path):
    """A grid over (BRDF, finest width) with the width varying fastest: run in index
    order, every point would need another reference than the last; scheduled by key, one
    geometry and one reference per width are made."""
    from pmdsim.run.sweep import run_sweep

    sweep = {"decimation": 0, "parameters": {"brdf.alpha_x": [0.004, 0.01, 0.03],
                                             "patterns.fringes.widths_px.0": [50.0, 100.0,
                                                                              25.0]}}
    sw.GEOMETRIES.clear()
    sw.REFERENCES.clear()
    res = run_sweep(parse_config(_config(sweep)), tmp_path / "s", scheduler="synchronous",
                    figures=False)
    assert len(res.computed) == 9
    assert (sw.GEOMETRIES.made, sw.GEOMETRIES.reused) == (1, 8)
    assert (sw.REFERENCES.made, sw.REFERENCES.reused) == (3, 6)
