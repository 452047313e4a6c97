"""The run as steps with the writing behind them: the dataset written in parts is the
dataset written at once (same arrays, bytes and attributes), the writing starts before the
chain ends, and the manifest comes last, after every file is complete."""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest

from pmdsim.config import parse_config
from test_pipeline import tiny_config_dict


def _dataset(rng):
    """A small dataset shaped like a run's: image-like float64/float32/bool/uint8 variables
    on (row, col) with dx != dy shapes, string and numeric index coordinates, a non-index
    coordinate, a scalar and attributes."""
    import xarray as xr

    h, w = 5, 7
    ds = xr.Dataset(coords={"row": np.arange(h), "col": np.arange(w)})
    ds["surface_mask"] = (("row", "col"), rng.random((h, w)) > 0.3, {"description": "m"})
    ds["specular_u"] = (("row", "col"), rng.normal(size=(h, w)) * 1e3, {"units": "px"})
    ds = ds.assign_coords(direction=("direction", np.array(["x", "y"], dtype=object)),
                          width=("width", np.array([8.0, 32.0])))
    ds["fringes"] = (("direction", "width", "row", "col"),
                     rng.normal(size=(2, 2, h, w)).astype(np.float32), {"units": "1"})
    ds["exposure"] = ((), 1.25, {"units": "1"})
    ds.attrs = {"title": "t", "config_json": "{}"}
    return ds


def _grow(ds, rng):
    """What later steps add: a chain-like variable, new index and non-index
    coordinates, a per-dot table and changed attributes."""
    h, w = ds.sizes["row"], ds.sizes["col"]
    a = ds.assign(phase_deviation=(("direction", "row", "col"),
                                   rng.normal(size=(2, h, w)), {"units": "rad"}),
                  decode_flags=(("direction", "row", "col"),
                                rng.integers(0, 16, (2, h, w)).astype(np.uint8), {}))
    a = a.assign_attrs(statistics_json=json.dumps({"a": 1}))
    b = a.assign_coords(dot_u=("dot", np.array([1.5, 2.5, 3.5])))
    b = b.assign(dot_peak=(("dot",), np.array([0.1, 0.2, 0.3]), {"units": "1"}))
    b = b.assign_coords(surface_x_mm=("surface_x", np.linspace(-1, 1, 4)))
    b = b.assign(height_error_nm=(("surface_x",), rng.normal(size=4), {"units": "nm"}))
    return a, b.assign_attrs(statistics_json=json.dumps({"a": 1, "b": 2}))


def _same_store(p, q):
    import zarr

    ga, gb = zarr.open_group(p, mode="r"), zarr.open_group(q, mode="r")
    assert sorted(ga.array_keys()) == sorted(gb.array_keys())
    assert dict(ga.attrs) == dict(gb.attrs)
    for k in ga.array_keys():
        x, y = ga[k], gb[k]
        assert (x.dtype, x.shape, x.chunks) == (y.dtype, y.shape, y.chunks), k
        assert dict(x.attrs) == dict(y.attrs), k
        assert x.metadata.to_dict() == y.metadata.to_dict(), k
        xa, ya = x[...], y[...]
        assert xa.tobytes() == ya.tobytes() if xa.dtype != object else list(xa) == list(ya), k


def test_dataset_written_in_parts_is_the_dataset_written_at_once(tmp_path):
    import xarray as xr

    from pmdsim.store.writer import write_dataset
    from pmdsim.store.writer import DatasetWriter

    rng = np.random.default_rng(7)
    first = _dataset(rng)
    middle, final = _grow(first, rng)
    writer = DatasetWriter(tmp_path / "parts.zarr")
    for ds in (first, first, middle):  # an offer with nothing new writes nothing
        writer.offer(ds)
    writer.finish(final)
    write_dataset(final, tmp_path / "once.zarr")
    _same_store(tmp_path / "parts.zarr", tmp_path / "once.zarr")
    opened = xr.open_zarr(tmp_path / "parts.zarr")  # consolidated: no warning, all there
    assert set(opened.data_vars) == set(final.data_vars)
    assert set(opened.coords) == set(final.coords)
    assert opened.attrs["statistics_json"] == final.attrs["statistics_json"]
    assert "dot_u" in opened["dot_peak"].coords  # a non-index coordinate stays one


def test_a_failed_part_is_raised_by_finish(tmp_path):
    from pmdsim.store.writer import DatasetWriter

    rng = np.random.default_rng(1)
    (tmp_path / "taken.zarr").mkdir()  # the store exists: creating it fails
    (tmp_path / "taken.zarr" / "zarr.json").write_text("{}")
    writer = DatasetWriter(tmp_path / "taken.zarr")
    writer.offer(_dataset(rng))
    with pytest.raises(Exception):
        writer.finish(_dataset(rng))


def test_writing_runs_behind_the_chain_and_the_manifest_comes_last(tmp_path, monkeypatch):
    """While the run diagnoses (its last computing step) the rendered images are already
    in run.zarr; when the manifest is written no writer thread runs and every file is
    complete: the consolidated store holds every variable, statistics, summary, config,
    images and figures exist."""
    import xarray as xr

    from pmdsim.run import steps as member_mod
    from pmdsim.run import simulate as simulate_mod

    seen = {}
    manifest = simulate_mod.write_run_manifest

    def diagnose(m):  # the diagnose step (the diagnostics' thread started after the render)
        store = seen["folder"] / "run.zarr"
        seen["at_diagnose"] = sorted(p.name for p in store.iterdir()) if store.is_dir() else []
        return member_mod.diagnose(m)

    def write_run_manifest(folder, cfg, result, timings):
        seen["threads"] = sorted(t.name for t in threading.enumerate()
                                 if t.name.startswith(("pmdsim-dataset", "pmdsim-images")))
        ds = xr.open_zarr(folder / "run.zarr", consolidated=True)
        seen["variables"] = set(ds.data_vars)
        seen["files"] = sorted(p.name for p in folder.iterdir())
        seen["figures"] = sorted(p.name for p in (folder / "figures").iterdir())
        seen["images"] = all(p.is_file() and p.stat().st_size > 0 for p in result.image_paths)
        return manifest(folder, cfg, result, timings)

    monkeypatch.setattr(member_mod, "STEPS", tuple(
        (diagnose if step is member_mod.diagnose else step, timing)
        for step, timing in member_mod.STEPS))
    monkeypatch.setattr(simulate_mod, "write_run_manifest", write_run_manifest)
    original = member_mod.run_member

    def run_member(plan, cfg, sim, geometry, folder, *args, **kwargs):
        seen["folder"] = folder
        return original(plan, cfg, sim, geometry, folder, *args, **kwargs)

    monkeypatch.setattr(simulate_mod, "run_member", run_member)
    d = tiny_config_dict(fringes={"widths_px": [10, 40, 160], "shifts": 4})
    d["output"] = {"figures": True}
    res = simulate_mod.run_simulation(parse_config(d), tmp_path / "run")
    assert "fringes" in seen["at_diagnose"] and "phase_deviation" in seen["at_diagnose"]
    assert seen["threads"] == []
    final = xr.open_zarr(res.dataset_path)
    assert seen["variables"] == set(final.data_vars)
    assert {"height_error_nm", "fringes", "phase_deviation"} <= seen["variables"]
    assert any(v.startswith("diag_") for v in seen["variables"])
    assert {"run.zarr", "config.json", "statistics.json", "summary.txt", "fringes",
            "figures"} <= set(seen["files"]) and "pmdsim-run.json" not in seen["files"]
    assert seen["figures"] == ["overview.png", "setup.png", "surface_errors.png", "surface_psd.png"]
    assert seen["images"] and len(res.image_paths) == 2 * 3 * 4
    assert json.loads(final.attrs["statistics_json"]) == json.loads(
        (res.outdir / "statistics.json").read_text())


def test_a_fork_inside_paused_never_copies_a_held_dask_lock(tmp_path, monkeypatch):
    """A part being written holds Dask's tokenize lock; a figure process forked then would
    wait for it forever (it did, on a loaded machine). Forks happen inside
    ``writer.paused()``, which waits for the part: the child tokenizes at once."""
    import multiprocessing as mp
    import time

    import dask.tokenize as dt

    from pmdsim.store import writer as writing

    started = threading.Event()

    def slow_part(ds, path, create):
        with dt.tokenize_lock:
            started.set()
            time.sleep(1.0)

    monkeypatch.setattr(writing, "_write_part", slow_part)
    writer = writing.DatasetWriter(tmp_path / "s.zarr")
    writer.offer(_dataset(np.random.default_rng(3)))
    assert started.wait(30)
    with writer.paused():
        child = mp.get_context("fork").Process(target=dt.tokenize, args=(1,))
        child.start()
    child.join(60)
    hung = child.is_alive()
    if hung:
        child.kill()
    writer.close()
    assert not hung and child.exitcode == 0


def test_the_reconstructions_repetitions_in_two_threads_give_the_same_bytes(tmp_path,
                                                                            monkeypatch):
    """The reconstruct step repeats the reconstruction twice for its stated errors (moved
    coordinates, and the error's signed pattern), the second in a thread where Numba takes
    two threads: the statistics and the PSD errors are the bytes of the same run with both
    repetitions in turn. A reduced turned sphere (64 x 48 px, dx != dy grid of a rotated
    part, the Gauss rule's stated errors) so that every error is non-zero."""
    from pathlib import Path

    from pmdsim.config import load_config
    from pmdsim.run import reconstruction, run_simulation
    from pmdsim.store.schema import load_run

    d = load_config(Path(__file__).parents[2] / "examples" / "turned_sphere.toml").model_dump()
    d["camera"].update(resolution=(64, 48), pixel_pitch_mm=0.03)
    d["sampling"].update(n_rays=16, mode="rule", target_error_mrad=None)
    d["variants"] = [{"name": "kinematic", "brdf": d["variants"][1]["brdf"]}]
    d["reconstruct"]["spacing_mm"] = 1.0
    cfg = parse_config(d)
    calls = []
    real = reconstruction.pattern_moves

    def counted(*a, **k):
        calls.append(threading.current_thread().name)
        return real(*a, **k)

    monkeypatch.setattr(reconstruction, "pattern_moves", counted)
    out = {}
    for threads in (True, False):  # as the run decides (two threads here), then in turn
        if not threads:
            monkeypatch.setattr(reconstruction, "numba_takes_two_threads", lambda: False)
        run_simulation(cfg, tmp_path / str(threads), diagnostics=False)
        if threads and not calls[0].startswith("pmdsim-pattern"):
            pytest.skip("Numba's threading layer takes parallel kernels from one thread only")
        ds = load_run(tmp_path / str(threads), variant="kinematic")
        out[threads] = ((tmp_path / str(threads) / "kinematic" / "statistics.json").read_bytes(),
                        {v: ds[v].values for v in ds.data_vars if v.endswith("_err")})
    assert calls[0].startswith("pmdsim-pattern") and calls[1] == threading.main_thread().name
    rec = json.loads(out[True][0])["reconstruction"]
    assert rec["height_error_nm"]["rms_err"] > 0 and rec["areal"]["height_error_nm"]["sdq_err"] > 0
    assert out[True][0] == out[False][0]
    assert out[True][1].keys() == out[False][1].keys() and "height_error_psd_err" in out[True][1]
    for v, a in out[True][1].items():
        assert np.array_equal(a, out[False][1][v], equal_nan=True), v


def _fig3_small(**sampling):
    """Fig. 3 on a 96 x 64 camera (the same field of view), its target's pilot, no
    figures or images."""
    import tomllib
    from pathlib import Path

    d = tomllib.loads((Path(__file__).parents[2] / "examples" / "paper_fig3.toml").read_text())
    d["camera"].update(resolution=[96, 64], pixel_pitch_mm=0.0048 * 1280 / 96)
    d["sampling"].update(sampling)
    d["output"] = {"figures": False, "write_images": False}
    return parse_config(d)


def test_the_pilot_made_beside_the_reference_gives_the_same_bytes(tmp_path, monkeypatch):
    """The pilot's choice of the rule runs in a thread from the run's start (beside the
    vision rays and the specular reference) where Numba takes two threads: statistics.json
    (the rule, every ray traced, the stated errors) and the stated phase errors are the
    bytes of the run whose render step makes the choice itself."""
    from pmdsim.render import Simulation
    from pmdsim.run import run_simulation, simulate
    from pmdsim.store.schema import load_run

    cfg = _fig3_small(target_error_mrad=0.1, n_rays=16)
    calls = []
    real = Simulation.choose_rule

    def counted(self, *a, **k):
        calls.append(threading.current_thread().name)
        return real(self, *a, **k)

    monkeypatch.setattr(Simulation, "choose_rule", counted)
    out = {}
    for early in (True, False):
        if not early:
            monkeypatch.setattr(simulate, "start_pilot", lambda cfg, sim: None)
        run_simulation(cfg, tmp_path / str(early), diagnostics=False)
        if early and not calls[0].startswith("pmdsim-pilot"):
            pytest.skip("Numba's threading layer takes parallel kernels from one thread only")
        ds = load_run(tmp_path / str(early))
        out[early] = ((tmp_path / str(early) / "statistics.json").read_bytes(),
                      ds["fringe_phase_error"].values if "fringe_phase_error" in ds else None)
    assert calls[0].startswith("pmdsim-pilot") and calls[1] == threading.main_thread().name
    stats = json.loads(out[True][0])
    assert stats["sampling"]["pilot"]["orders_tried"][0] == 16 and stats["sampling"]["n_rays"] > 16
    assert stats["sampling"]["rays_traced"] > 0
    assert out[True][0] == out[False][0]
    assert out[True][1] is not None and np.array_equal(out[True][1], out[False][1],
                                                       equal_nan=True)


def test_a_run_that_fails_before_its_render_stops_its_pilot(tmp_path, monkeypatch):
    """A run whose vision rays fail after the pilot started: the error is the run's, no
    folder is left, and the pilot's thread is stopped (it ends before run_simulation
    returns); a pilot cancelled before its first probe raises Cancelled."""
    from pmdsim.render import Simulation
    from pmdsim.render.pilot import Cancelled
    from pmdsim.run import run_simulation

    cfg = _fig3_small(target_error_mrad=0.1, n_rays=16)

    def broken(self):
        raise RuntimeError("geometry failed")

    monkeypatch.setattr(Simulation, "geometry", broken)
    with pytest.raises(RuntimeError, match="geometry failed"):
        run_simulation(cfg, tmp_path / "run", diagnostics=False)
    assert not (tmp_path / "run").exists()
    assert not [t for t in threading.enumerate() if t.name.startswith("pmdsim-pilot")]
    stop = threading.Event()
    stop.set()
    fr = cfg.patterns.fringes
    with pytest.raises(Cancelled):
        Simulation.from_config(cfg).choose_rule(fr.widths_px, fr.directions, fr.shifts, stop)
