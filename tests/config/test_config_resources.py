"""The memory and time estimate of a configuration (:func:`pmdsim.config.estimate_resources`)
and the check that stops a run that cannot fit before anything is allocated."""

from __future__ import annotations

from pathlib import Path

import pytest

from conftest import make_config
from pmdsim.config import ConfigError, check_resources, estimate_resources, load_config

EXAMPLES = Path(__file__).parents[2] / "examples"
GB = 2**30


def _first_field(msg: str) -> str:
    return msg.splitlines()[1].strip().split(":")[0]


def test_memory_grows_with_the_camera_pixels_and_the_fringe_images():
    small = estimate_resources(make_config())
    big = estimate_resources(make_config(camera={"resolution": [400, 320]}))
    # 100x the pixels: the per-pixel part grows 100x on top of the fixed interpreter base
    from pmdsim.config import BASE_MEMORY_BYTES
    per_px_small = small.memory_bytes - BASE_MEMORY_BYTES - small.parts.get("sampling.n_rays", 0)
    per_px_big = big.memory_bytes - BASE_MEMORY_BYTES - big.parts.get("sampling.n_rays", 0)
    assert per_px_big / per_px_small == pytest.approx(100, rel=0.15)
    more = estimate_resources(make_config(patterns={"fringes": {"widths_px": [20.0, 50.0, 400.0],
                                                                "shifts": 8}}))
    assert more.parts["patterns.fringes"] > 2 * small.parts["patterns.fringes"]
    # rays: pixels x rays per pixel x passes (+ the one-ray specular reference)
    assert big.rays == pytest.approx(400 * 320 * (48 + 1))


def test_a_huge_camera_is_refused_naming_its_resolution():
    # the focal length grows with the sensor: a huge camera, not a 180 deg field of view
    cfg = make_config(camera={"resolution": [60000, 60000], "focal_length_px": 120000.0})
    with pytest.raises(ConfigError) as info:
        check_resources(cfg, available_bytes=64 * GB)
    msg = str(info.value)
    assert _first_field(msg) == "camera.resolution" and "64 GB" in msg


def test_too_many_rays_are_refused_naming_n_rays():
    cfg = make_config(sampling={"n_rays": 10_000_000, "max_rays": 10_000_000})
    with pytest.raises(ConfigError) as info:
        check_resources(cfg, available_bytes=16 * GB)
    assert _first_field(str(info.value)) == "sampling.n_rays"


def test_too_many_dots_are_refused_naming_the_dots():
    cfg = make_config(camera={"resolution": [1280, 1024]},
                      patterns={"fringes": False, "dots": {"grid": [100, 100]}})
    with pytest.raises(ConfigError) as info:
        check_resources(cfg, available_bytes=16 * GB)
    assert _first_field(str(info.value)) == "patterns.dots"


def test_cpu_time_over_the_limit_is_refused_and_the_limit_can_be_raised():
    cfg = make_config(camera={"resolution": [2000, 2000]}, sampling={"n_rays": 1_000_000, "max_rays": 1_000_000})
    with pytest.raises(ConfigError) as info:
        check_resources(cfg, available_bytes=10**15)
    assert _first_field(str(info.value)) == "sampling.n_rays"
    assert "compute.max_cpu_hours" in str(info.value)
    raised = make_config(camera={"resolution": [2000, 2000]}, sampling={"n_rays": 1_000_000, "max_rays": 1_000_000},
                         compute={"max_cpu_hours": 1e6})
    check_resources(raised, available_bytes=10**15)


@pytest.mark.parametrize("name", ["paper_fig3.toml", "roughness_comparison.toml", "dot_scan.toml"])
def test_the_examples_fit_a_laptop(name):
    est = check_resources(load_config(EXAMPLES / name), available_bytes=8 * GB)
    assert est.memory_bytes < 4 * GB


# ----------------------------------------------------------------------------- vs real runs
FACTORS = {
    "plain": {},
    "subpixels": {"camera": {"subpixels": 2}},
    "thin_lens": {"camera": {"focal_length_mm": 16.0, "pixel_pitch_mm": 0.2,
                             "focal_length_px": None, "f_number": 8.0, "aperture_samples": 3}},
    "continuous_harmonics": {"monitor": {"pixel_model": "continuous", "gamma": 2.2}},
    "many_rays": {"sampling": {"n_rays": 600}},
}


def _traced_run(cfg, tmp_path):
    """Peak of the arrays (tracemalloc) of a whole run, after a first run of the same
    configuration (the modules it imports are the interpreter's base, not the run's)."""
    import tracemalloc

    from pmdsim.run import run_simulation

    run_simulation(cfg, tmp_path / "warm", figures=False, diagnostics=False)
    tracemalloc.start()
    try:
        run_simulation(cfg, tmp_path / "run", figures=False, diagnostics=False)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak


def _rays_rendered(cfg) -> tuple[int, int]:
    """(vision rays of the first pass, scattered rays of all passes) of one fringe render,
    counted as the renderer hands the vision rays (bundle geometry rows) to the kernel, each
    with the bundle size of the pass's sample set."""
    import pmdsim.render.simulation as rs
    from pmdsim.render import Simulation

    rows, rays, bundle = [], [0], [0]
    originals = {k: getattr(rs, k) for k in ("scene_geometry_rows", "vision_geometry_rows")}
    render_brdf = Simulation._render_brdf

    def counting(fn):
        def wrapped(*args, **kwargs):
            geo, spec = fn(*args, **kwargs)
            if bundle[0]:
                rows[-1] += geo.shape[0]
                rays[0] += geo.shape[0] * bundle[0]
            return geo, spec
        return wrapped

    def one_pass(self, scene, *args, **kwargs):
        # the rays the kernel runs per vision ray: the pass's own set (one rqmc replicate,
        # the rule or its embedded rule), as many as its per-ray weights
        bundle[0] = (1 if scene.brdf.is_delta else
                     scene.sampling.ray_weights(scene.estimator == "radiometric").size)
        rows.append(0)
        try:
            return render_brdf(self, scene, *args, **kwargs)
        finally:
            bundle[0] = 0

    sim = Simulation.from_config(cfg)
    try:
        for k, fn in originals.items():
            setattr(rs, k, counting(fn))
        Simulation._render_brdf = one_pass
        sim.render_fringes()
    finally:
        for k, fn in originals.items():
            setattr(rs, k, fn)
        Simulation._render_brdf = render_brdf
    return rows[0], rays[0]


@pytest.mark.parametrize("name", list(FACTORS))
def test_the_estimate_covers_the_arrays_and_counts_the_rays_of_real_runs(tmp_path, name):
    """Each factor of the estimate against a direct count on a real tiny run: the peak of
    the arrays the run allocates (tracemalloc) lies under the estimate (without the
    interpreter's base) and not far below it; the rays bound those the renderer traces
    (the vision rays counted as they reach the kernel, times the bundle size of each pass:
    the rule and its embedded rule, or the rqmc replicates), plus the one-ray specular
    reference."""
    from pmdsim.config import BASE_MEMORY_BYTES

    cfg = make_config(**FACTORS[name])
    est = estimate_resources(cfg)
    peak = _traced_run(cfg, tmp_path)
    budget = est.memory_bytes - BASE_MEMORY_BYTES
    assert peak <= budget, (name, peak, est.parts)
    # not absurdly high, for what this run allocates: it runs without the diagnostics,
    # whose ray transport the estimate holds (each grid pixel keeps every ray)
    from pmdsim.config.resources import _TRANSPORT_BYTES_PER_RAY, rays_per_bundle

    gx, gy = cfg.diagnostics.grid
    transport = min(est.parts.get("sampling.n_rays", 0.0),
                    rays_per_bundle(cfg.sampling, cfg.monitor.pixel_model)
                    * _TRANSPORT_BYTES_PER_RAY * gx * gy)
    assert budget - transport < 30 * peak, (name, peak, est.parts)
    w, h = cfg.camera.resolution
    vision_rays, rays = _rays_rendered(cfg)
    vision = vision_rays / (w * h)
    # an upper bound (the rule's node count and the embedded rule are bounded, not
    # exact), never below the count, at most 2x above it; + the one-ray reference
    assert rays + w * h * vision <= est.rays <= 2 * rays + w * h * vision
    assert vision == {"subpixels": 4, "thin_lens": 3}.get(name, 1)
    if vision > 1:
        field = "camera.subpixels" if name == "subpixels" else "camera.aperture_samples"
        assert est.parts[field] == pytest.approx(w * h * 200 * (vision - 1))


def test_many_aperture_samples_are_refused_naming_them():
    cfg = make_config(camera={"resolution": [1280, 1024], "focal_length_mm": 16.0,
                              "pixel_pitch_mm": 0.005, "focal_length_px": None,
                              "f_number": 8.0, "aperture_samples": 100_000})
    with pytest.raises(ConfigError) as info:
        check_resources(cfg, available_bytes=64 * GB)
    assert _first_field(str(info.value)) == "camera.aperture_samples"


def test_the_cpu_limit_names_the_factor_that_multiplies_the_rays():
    lens = {"focal_length_mm": 16.0, "pixel_pitch_mm": 0.2, "focal_length_px": None,
            "f_number": 8.0, "aperture_samples": 4000}
    cfg = make_config(camera=lens, sampling={"n_rays": 48})
    with pytest.raises(ConfigError) as info:
        check_resources(cfg, available_bytes=10**15, max_cpu_hours=1e-4)
    assert _first_field(str(info.value)) == "camera.aperture_samples"
    with pytest.raises(ConfigError) as info:
        check_resources(make_config(sampling={"n_rays": 100_000, "max_rays": 100_000}),
                        available_bytes=10**15,
                        max_cpu_hours=1e-4)
    assert _first_field(str(info.value)) == "sampling.n_rays"
    # the limit scales the refusal: the same run is accepted with a limit above its time
    est = estimate_resources(cfg)
    check_resources(cfg, available_bytes=10**15, max_cpu_hours=1.01 * est.cpu_seconds / 3600)


def test_the_reconstruction_grid_is_counted_node_by_node(tmp_path, monkeypatch):
    """The grid nodes of the estimate against the grid of a real reconstruction, and its
    memory against the peak the reconstruction's arrays reach (tracemalloc)."""
    import tracemalloc

    import pmdsim.run.reconstruction as rr
    from pmdsim.config.resources import RECONSTRUCTION_BYTES_PER_NODE, reconstruction_nodes
    from pmdsim.run import run_simulation

    seen = {}
    real = rr.reconstruct

    def counted(*args, **kwargs):
        tracemalloc.start()
        try:
            rec = real(*args, **kwargs)
            seen["peak"] = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        seen["nodes"] = rec.x_mm.size * rec.y_mm.size
        return rec

    monkeypatch.setattr(rr, "reconstruct", counted)
    cfg = make_config(reconstruct={"spacing_mm": 0.7}, sampling={"n_rays": 48, "mode": "stratified"},
                      patterns={"fringes": {"widths_px": [10.0, 40.0, 200.0]}})
    run_simulation(cfg, tmp_path / "run", figures=False, diagnostics=False)
    assert reconstruction_nodes(cfg) == seen["nodes"]
    assert seen["peak"] < seen["nodes"] * RECONSTRUCTION_BYTES_PER_NODE
    assert estimate_resources(cfg).parts["reconstruct.spacing_mm"] == \
        seen["nodes"] * RECONSTRUCTION_BYTES_PER_NODE
    # one width cannot be decoded: no reconstruction, nothing counted
    assert reconstruction_nodes(make_config()) == 0


def test_a_huge_aperture_is_refused_naming_the_reconstruction_grid():
    cfg = make_config(surface={"__replace__": {"type": "sphere", "radius_mm": 1e7,
                                               "aperture": {"radius_mm": 1e6}}},
                      patterns={"fringes": {"widths_px": [10.0, 40.0, 200.0]}})
    with pytest.raises(ConfigError) as info:
        check_resources(cfg, available_bytes=64 * GB)
    assert _first_field(str(info.value)) == "reconstruct.spacing_mm"


def test_sweeps_are_sized_per_point_and_in_total():
    from pmdsim.config.resources import MAX_SWEEP_POINTS, check_study, check_sweep_size

    big = make_config(sweep={"parameters": {"brdf.alpha_x": [0.01 + i * 1e-5 for i in range(1000)],
                                            "brdf.alpha_y": [0.002 + i * 1e-6 for i in range(1000)]}})
    with pytest.raises(ConfigError) as info:
        check_sweep_size(big)
    assert _first_field(str(info.value)) == "sweep.parameters" and "1,000,000" in str(info.value)
    assert check_sweep_size(make_config(sweep={"parameters": {"brdf.alpha_x": [0.01, 0.02]}})) == 2
    assert MAX_SWEEP_POINTS >= 10_000
    points = [make_config(sampling={"n_rays": n, "max_rays": max(n, 65536)})
              for n in (48, 10_000_000, 64)]
    with pytest.raises(ConfigError) as info:
        check_study(points, "sweep.parameters", labels=["a", "b", "c"],
                    available_bytes=16 * GB)
    msg = str(info.value)
    assert _first_field(msg) == "sweep.parameters" and " b needs" in msg and "sampling.n_rays" in msg
    # in total: each point fits, all together exceed the CPU limit
    small = [make_config() for _ in range(5)]
    one = estimate_resources(small[0]).cpu_seconds
    with pytest.raises(ConfigError, match="5 runs need"):
        check_study(small, "sweep.parameters", available_bytes=16 * GB,
                    max_cpu_hours=3 * one / 3600)
    est = check_study(small, "sweep.parameters", concurrent=2, available_bytes=16 * GB,
                      max_cpu_hours=6 * one / 3600)
    from pmdsim.config import BASE_MEMORY_BYTES
    single = estimate_resources(small[0]).memory_bytes
    assert est.memory_bytes == BASE_MEMORY_BYTES + 2 * (single - BASE_MEMORY_BYTES)
