"""The run's specular reference: its reconstruction, computed in a thread while the run
goes on, is the one computed inline, and its errors reach the run."""

from __future__ import annotations

from concurrent.futures import Future

import numpy as np
import pytest

from pmdsim.config import parse_config
from pmdsim.render import Simulation
from pmdsim.run import reference as ref
from pmdsim.run.result import _Steps
from test_pipeline import tiny_config_dict


@pytest.fixture(scope="module")
def setup():
    cfg = parse_config(tiny_config_dict(fringes={"widths_px": [10, 40, 160], "shifts": 4}))
    sim = Simulation.from_config(cfg)
    return cfg, sim, sim.geometry()


def _reference(setup, threaded, monkeypatch):
    cfg, sim, geometry = setup
    monkeypatch.setattr(ref, "numba_takes_two_threads", lambda: threaded)
    n_tiles = -(-sim.shape[0] // sim.tile_rows)
    return ref.specular_reference(cfg, sim, geometry, _Steps(None, 10 * n_tiles), n_tiles)


def test_threaded_reference_reconstruction_is_the_inline_one(setup, monkeypatch):
    inline = _reference(setup, False, monkeypatch)
    threaded = _reference(setup, True, monkeypatch)
    assert not isinstance(inline._reconstruction, Future)
    assert isinstance(threaded._reconstruction, Future)
    (r0, e0), (r1, e1) = inline.reconstruction, threaded.reconstruction
    np.testing.assert_array_equal(r0.height_mm, r1.height_mm)
    np.testing.assert_array_equal(e0.height_nm, e1.height_nm)
    assert np.isfinite(e0.height_nm).any()


def test_an_error_of_the_threaded_reconstruction_is_raised_where_it_is_read(setup,
                                                                            monkeypatch):
    from pmdsim.run import reconstruction as recon

    def fails(*args, **kwargs):
        raise RuntimeError("reference reconstruction failed")

    monkeypatch.setattr(recon, "reference_reconstruction", fails)
    r = _reference(setup, True, monkeypatch)  # the run goes on
    with pytest.raises(RuntimeError, match="reference reconstruction failed"):
        r.reconstruction



def test_the_run_forks_its_figures_only_after_the_reference_thread(tmp_path, monkeypatch):
    """A fork while the reference's reconstruction runs a DCT in its thread shuts SciPy's
    pocketfft pool under it ("Work item submitted after shutdown"): the run waits for the
    thread before its first figure process (here the thread is made slow on purpose)."""
    import threading
    import time

    from pmdsim.run import figures as figures_mod
    from pmdsim.run import reconstruction as recon
    from pmdsim.run.simulate import run_simulation

    slow_done = []
    original = recon.reference_reconstruction

    def slow(*args, **kwargs):
        time.sleep(1.5)
        out = original(*args, **kwargs)
        slow_done.append(True)
        return out

    alive_at_fork = []
    start = figures_mod.start_drawings

    def start_drawings(names, *args, **kwargs):
        alive_at_fork.append(any(t.name.startswith("pmdsim-reference-reconstruction")
                                 for t in threading.enumerate()))
        return start(names, *args, **kwargs)

    monkeypatch.setattr(ref, "numba_takes_two_threads", lambda: True)
    monkeypatch.setattr(recon, "reference_reconstruction", slow)
    monkeypatch.setattr(figures_mod, "start_drawings", start_drawings)
    d = tiny_config_dict(fringes={"widths_px": [10, 40, 160], "shifts": 4})
    d["output"] = {"figures": True, "write_images": False}
    res = run_simulation(parse_config(d), tmp_path / "run")
    assert slow_done == [True]
    assert alive_at_fork and not any(alive_at_fork)
    assert sorted(p.name for p in res.figure_paths) == [
        "overview.png", "setup.png", "surface_errors.png", "surface_psd.png"]


def test_a_failed_run_leaves_no_reference_thread_behind(tmp_path, monkeypatch):
    import threading
    import time

    from pmdsim.run import reconstruction as recon
    from pmdsim.run.simulate import run_simulation

    original = recon.reference_reconstruction

    def slow(*args, **kwargs):
        time.sleep(1.0)
        return original(*args, **kwargs)

    def fails(*args, **kwargs):
        raise RuntimeError("the member failed")

    monkeypatch.setattr(ref, "numba_takes_two_threads", lambda: True)
    monkeypatch.setattr(recon, "reference_reconstruction", slow)
    monkeypatch.setattr("pmdsim.run.simulate.run_member", fails)
    d = tiny_config_dict(fringes={"widths_px": [10, 40, 160], "shifts": 4})
    with pytest.raises(RuntimeError, match="the member failed"):
        run_simulation(parse_config(d), tmp_path / "run")
    assert not any(t.name.startswith("pmdsim-reference-reconstruction") for t in threading.enumerate())
    assert not (tmp_path / "run").exists()
