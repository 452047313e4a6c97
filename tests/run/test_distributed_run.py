"""One run across a Dask cluster (``run_simulation(..., client=)``, ``pmdsim simulate
--scheduler tcp://...``): the same bytes as a local run, its tiles spread over the
cluster's workers (a LocalCluster of two in-process workers: fast)."""

from __future__ import annotations

import pytest

from pmdsim.config import parse_config
from pmdsim.run.simulate import run_simulation
from test_pipeline import tiny_config_dict

distributed = pytest.importorskip("distributed")


def _config():
    d = tiny_config_dict(fringes={"widths_px": [10, 40, 160], "shifts": 4},
                         dots={"size_px": 9, "grid": [2, 1], "margin_px": 30})
    d["sampling"] = {"n_rays": 12, "theta_max_deg": 1.0, "mode": "random", "seed": 5}
    d["compute"] = {"tile_rows": 6}
    d["reconstruct"] = {"enabled": False}  # (its solver's last bits vary from run to run)
    d["output"] = {"figures": False}
    return parse_config(d)


def _arrays(folder):
    import zarr

    g = zarr.open_group(folder / "run.zarr", mode="r")
    return {k: g[k][...] for k in g.array_keys()}, dict(g.attrs)


def test_a_run_on_a_cluster_has_the_bytes_of_a_local_run(tmp_path):
    cfg = _config()
    local = run_simulation(cfg, tmp_path / "local")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        with distributed.get_task_stream(client) as stream:
            remote = run_simulation(cfg, tmp_path / "cluster", client=client)
    tiles = [t for t in stream.data if str(t["key"]).startswith("pmdsim-tile")]
    # every render call's tiles ran on the cluster, over both workers
    n_tiles = -(-cfg.camera.resolution[1] // cfg.compute.tile_rows)
    assert len(tiles) >= 3 * n_tiles  # geometry, reference, fringes, dots
    assert len({t["worker"] for t in tiles}) == 2
    a, attrs_a = _arrays(local.outdir)
    b, attrs_b = _arrays(remote.outdir)
    assert sorted(a) == sorted(b) and "fringes" in a and "phase_deviation" in a
    for k in a:
        assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape, k
        if a[k].dtype == object:
            assert list(a[k].ravel()) == list(b[k].ravel()), k
        else:
            assert a[k].tobytes() == b[k].tobytes(), k
    attrs_a.pop("created_utc"), attrs_b.pop("created_utc")
    assert attrs_a == attrs_b  # the stored configuration too: compute.scheduler unchanged
    for p, q in zip(local.image_paths, remote.image_paths):
        assert p.name == q.name and p.read_bytes() == q.read_bytes()
    assert (local.outdir / "statistics.json").read_text() == \
        (remote.outdir / "statistics.json").read_text()


def test_cli_scheduler_needs_an_address(tmp_path):
    from typer.testing import CliRunner

    from pmdsim.cli import app

    from test_pipeline import TOML

    cfg = tmp_path / "c.toml"
    cfg.write_text(TOML.format(pitch_key="pixel_pitch_mm"))
    res = CliRunner().invoke(app, ["simulate", str(cfg), "-o", str(tmp_path / "o"),
                                   "--scheduler", "nowhere"])
    assert res.exit_code == 2
    assert "--scheduler: 'nowhere' is not a Dask scheduler address" in res.output
    assert not (tmp_path / "o").exists()
