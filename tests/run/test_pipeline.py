"""The run pipeline and the command line on a tiny scene (48 x 40 camera, 160 x 90 monitor,
N = 10): run folder contents, the dataset, reproducibility from the stored config, image
scaling, atomic outputs, and the CLI."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from pmdsim import run as pipeline

from pmdsim.store import schema
from pmdsim.store.writer import KEEP_BITS, keep_bits
from pmdsim.config import RunConfig, parse_config
from pmdsim.render import Simulation
from pmdsim.store.folder import MANIFEST, is_run_dir
from pmdsim.store.images import read_image

S25, C25 = math.sin(math.radians(25)), math.cos(math.radians(25))


def tiny_config_dict(**patterns) -> dict:
    """The paper's Fig. 3 geometry shrunk to 48 x 40 camera px and 160 x 90 monitor px."""
    return {
        "name": "tiny",
        "camera": {"resolution": [48, 40], "focal_length_px": 50 / 0.0048 * 48 / 1280,
                   "position_mm": [-2000 * S25, 0.0, 2000 * C25], "look_at_mm": [0, 0, 0]},
        "monitor": {"resolution": [160, 90], "pixel_pitch_mm": 3.0,
                    "centre_mm": [600 * S25, 0.0, 600 * C25], "look_at_mm": [0, 0, 0]},
        "surface": {"type": "flat", "size_mm": [300.0, 200.0]},
        "anisotropy": {"frame": "fixed", "x_direction": [1, 0, 0]},
        "brdf": {"model": "ward", "alpha_x": 0.025, "alpha_y": 0.002, "rho_s": 0.4},
        "sampling": {"n_rays": 10, "theta_max_deg": 1.0, "mode": "stratified"},  # the lattice: its diagnostics are tested here
        "patterns": patterns or {"fringes": {"widths_px": [8, 32], "shifts": 4}},
        "compute": {"tile_rows": 16},
        "output": {"figures": False},
    }


TOML = """
name = "tiny-cli"
[camera]
resolution = [48, 40]
focal_length_px = 390.625
position_mm = [-845.2365, 0.0, 1812.6156]
look_at_mm = [0.0, 0.0, 0.0]
[monitor]
resolution = [160, 90]
{pitch_key} = 3.0
centre_mm = [253.571, 0.0, 543.785]
look_at_mm = [0.0, 0.0, 0.0]
[surface]
type = "flat"
size_mm = [300.0, 200.0]
[brdf]
model = "ward"
alpha_x = 0.025
alpha_y = 0.002
[sampling]
n_rays = 10
mode = "stratified"
[patterns.fringes]
widths_px = [8.0]
shifts = 4
[compute]
tile_rows = 20
"""


@pytest.fixture(scope="module")
def monitor_image(tmp_path_factory) -> Path:
    import tifffile

    path = tmp_path_factory.mktemp("inputs") / "ramp.tif"
    ramp = np.broadcast_to(np.linspace(0, 255, 160).astype(np.uint8), (90, 160))
    tifffile.imwrite(path, np.ascontiguousarray(ramp))
    return path


@pytest.fixture(scope="module")
def full_cfg(monitor_image) -> RunConfig:
    d = tiny_config_dict(
        fringes={"widths_px": [8, 32], "shifts": 4},
        dots={"size_px": 9, "grid": [2, 1], "margin_px": 30, "positions_px": [[80, 45]]},
        images={"files": [str(monitor_image)]},
    )
    d["output"] = {"figures": True}
    return parse_config(d)


@pytest.fixture(scope="module")
def full_run(full_cfg, tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "full"
    calls = []
    result = pipeline.run_simulation(full_cfg, out, lambda d, t: calls.append((d, t)))
    return result, calls


def _siblings(path: Path) -> list[Path]:
    return [p for p in path.parent.iterdir() if p.name.startswith(path.name + ".")]


def test_run_folder_contents(full_run):
    result, _ = full_run
    out = result.outdir
    manifest = json.loads((out / MANIFEST).read_text())
    assert (out / "run.zarr").is_dir() and (out / "config.json").is_file()
    fringe_files = sorted(p.name for p in (out / "fringes").iterdir())
    assert len(fringe_files) == 2 * 2 * 4
    assert fringe_files[0] == "x_w008_k0.tif" and "y_w032_k3.tif" in fringe_files
    assert sorted(p.name for p in (out / "dots").iterdir()) == [
        "dot000_u0030_v0044.tif", "dot001_u0129_v0044.tif", "dot002_u0080_v0045.tif"]
    assert [p.name for p in (out / "images").iterdir()] == ["00_ramp.tif"]
    # widths [8, 32] cannot be unwrapped over 160 monitor px: decoding is skipped (a note);
    # the dots get their moments (dots.csv) and figures.
    assert sorted(p.name for p in (out / "figures").iterdir()) == [
        "dot_contact_sheet.png", "dot_shapes.png", "fringes.png", "modulation.png", "setup.png"]
    assert (out / "dots.csv").is_file()
    # nothing decoded: statistics.json holds the run diagnostics alone
    stats = json.loads((out / "statistics.json").read_text())
    assert "directions" not in stats and stats["diagnostics"]["estimator"] == "paper"
    assert any("decoding skipped" in n and "patterns.fringes.widths_px" in n
               for n in manifest["notes"])
    assert len(manifest["images"]) == 16 + 3 + 1
    assert all((out / p).is_file() for p in manifest["images"] + manifest["figures"])
    assert manifest["exposure"] == pytest.approx(result.exposure)
    assert result.rays_traced == result.surface_pixels * 10 * 3
    assert _siblings(out) == []


def test_progress_reaches_total(full_run):
    _, calls = full_run
    done = [d for d, _ in calls]
    totals = {t for _, t in calls}
    assert len(totals) == 1 and done == sorted(done)
    # geometry + 3 render calls x 3 tiles + images + diagnostics + dataset + figures
    assert done[-1] == totals.pop() == 1 + 3 * 3 + 4


def test_dataset_matches_simulation(full_run, full_cfg):
    result, _ = full_run
    ds = schema.load_run(result.outdir)
    assert dict(ds.sizes) == {"row": 40, "col": 48, "direction": 2, "width": 2, "shift": 4,
                              "dot": 3, "image": 1, "diag_row": 20, "diag_col": 24}
    assert ds["fringes"].dims == ("direction", "width", "shift", "row", "col")
    assert ds["fringes"].dtype == np.float32
    assert list(ds["width"].values) == [8.0, 32.0]
    assert ds["width"].attrs["units"] == "monitor px"
    np.testing.assert_allclose(ds["shift"].values, np.arange(4) * np.pi / 2)
    assert [str(d) for d in ds["direction"].values] == ["x", "y"]
    assert ds.attrs["pmdsim_version"] and ds.attrs["rays_per_pixel"] == 10
    assert float(ds["exposure"]) == pytest.approx(result.exposure)

    sim = Simulation.from_config(full_cfg)
    geo = sim.geometry()
    np.testing.assert_array_equal(ds["surface_mask"].values, geo.surface_mask)
    np.testing.assert_array_equal(ds["monitor_mask"].values, geo.monitor_mask)
    # stored as docs/outputs.md says: exact specular points and fringe sums in full float32,
    # camera values and the other weight sums in float32 with KEEP_BITS significant bits
    np.testing.assert_array_equal(ds["specular_u"].values, geo.specular_u.astype(np.float32))
    np.testing.assert_array_equal(ds["specular_v"].values, geo.specular_v.astype(np.float32))
    fr = sim.render_fringes((8, 32), ("x", "y"), 4)
    np.testing.assert_array_equal(ds["fringes"].values, keep_bits(fr.images))
    # the fringe sums in full float32 (their phase within the stated error: test_pilot.py)
    np.testing.assert_array_equal(ds["fringe_sums_real"].values, fr.sums.real.astype(np.float32))
    np.testing.assert_array_equal(ds["fringe_sums_imag"].values, fr.sums.imag.astype(np.float32))
    np.testing.assert_array_equal(ds["f_hit"].values, keep_bits(fr.f_hit))
    assert ds["dots"].shape == (3, 40, 48) and ds["images"].shape == (1, 40, 48)
    assert list(ds["dot_u"].values) == [30.0, 129.0, 80.0]
    # Pixels that miss the surface are NaN in the dataset (and 0 in the image files).
    assert np.all(np.isnan(ds["fringes"].values[..., ~geo.surface_mask]))


def test_config_round_trips_and_rerun_is_identical(full_run, full_cfg, tmp_path):
    result, _ = full_run
    ds = schema.load_run(result.dataset_path)
    cfg = RunConfig.model_validate_json(ds.attrs["config_json"])
    assert cfg == full_cfg == schema.run_config(ds)
    again = pipeline.run_simulation(cfg, tmp_path / "again", figures=False)
    ds2 = schema.load_run(again.outdir)
    for name in ("fringes", "fringe_sums_real", "fringe_sums_imag", "f_total", "dots",
                 "images", "specular_u"):
        np.testing.assert_array_equal(ds2[name].values, ds[name].values, err_msg=name)
    assert again.exposure == result.exposure
    for rel in json.loads((result.outdir / MANIFEST).read_text())["images"]:
        np.testing.assert_array_equal(read_image(again.outdir / rel),
                                      read_image(result.outdir / rel), err_msg=rel)


def test_tiffs_are_uint16_with_documented_scaling(full_run):
    result, _ = full_run
    ds = schema.load_run(result.outdir)
    values = {"fringes": ds["fringes"].values, "dots": ds["dots"].values,
              "images": ds["images"].values}
    peak = max(np.nanmax(v) for v in values.values())
    # the dataset keeps KEEP_BITS significant bits of the values the files were scaled from
    assert result.exposure == pytest.approx(0.95 * 65535 / peak, rel=2.0 ** -KEEP_BITS)
    tif = read_image(result.outdir / "fringes" / "y_w032_k1.tif")
    assert tif.dtype == np.uint16 and tif.shape == (40, 48)
    ref = values["fringes"][1, 1, 1].astype(np.float64) * result.exposure
    expected = np.where(np.isnan(ref), 0, np.rint(ref)).astype(np.uint16)
    # within one count: the stored value is the file's value to 2**-17 relative
    diff = np.abs(tif.astype(np.int64) - expected.astype(np.int64))
    assert diff.max() <= 1 and np.mean(diff == 0) > 0.9
    brightest = max(read_image(p).max() for p in result.image_paths)
    assert brightest == round(0.95 * 65535)


def test_png_8bit_output(tmp_path):
    d = tiny_config_dict()
    d["output"] = {"image_format": "png", "bit_depth": 8, "figures": False}
    result = pipeline.run_simulation(parse_config(d), tmp_path / "png")
    names = sorted(p.name for p in result.image_paths)
    assert names[0] == "x_w008_k0.png" and len(names) == 16
    img = read_image(result.image_paths[0])
    assert img.dtype == np.uint8 and img.shape == (40, 48)
    assert max(read_image(p).max() for p in result.image_paths) == round(0.95 * 255)
    ds = schema.load_run(result.outdir)
    ref = ds["fringes"].values[0, 0, 0].astype(np.float64) * result.exposure
    np.testing.assert_array_equal(img, np.where(np.isnan(ref), 0, np.rint(ref)))


def test_failing_run_leaves_no_folder(tmp_path, monkeypatch):
    def boom(*args, **kwargs):
        raise RuntimeError("render failed")

    monkeypatch.setattr(Simulation, "render_fringes", boom)
    out = tmp_path / "fails"
    with pytest.raises(RuntimeError, match="render failed"):
        pipeline.run_simulation(parse_config(tiny_config_dict()), out)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_failing_overwrite_keeps_the_old_run(tmp_path, monkeypatch):
    cfg = parse_config(tiny_config_dict())
    out = tmp_path / "run"
    pipeline.run_simulation(cfg, out)
    before = (out / MANIFEST).read_text()

    def boom(*args, **kwargs):
        raise RuntimeError("dataset failed")

    from pmdsim.run import steps as member

    monkeypatch.setattr(member, "build_dataset", boom)
    with pytest.raises(RuntimeError):
        pipeline.run_simulation(cfg, out, overwrite=True)
    assert (out / MANIFEST).read_text() == before
    assert _siblings(out) == []


def test_existing_output_is_not_clobbered(tmp_path):
    cfg = parse_config(tiny_config_dict())
    precious = tmp_path / "precious"
    precious.mkdir()
    (precious / "thesis.tex").write_text("do not delete")
    for overwrite in (False, True):
        with pytest.raises(FileExistsError):
            pipeline.run_simulation(cfg, precious, overwrite=overwrite)
    assert (precious / "thesis.tex").read_text() == "do not delete"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["precious"]

    out = tmp_path / "run"
    first = pipeline.run_simulation(cfg, out)
    (out / "marker").write_text("from the first run")
    with pytest.raises(FileExistsError, match="--overwrite"):
        pipeline.run_simulation(cfg, out)
    assert (out / "marker").exists()
    second = pipeline.run_simulation(cfg, out, overwrite=True)
    assert not (out / "marker").exists() and is_run_dir(out)
    assert second.exposure == first.exposure
    assert _siblings(out) == []


def test_variants_become_sub_runs(tmp_path):
    d = tiny_config_dict()
    d["variants"] = [
        {"name": "mirror", "description": "ideal mirror", "brdf": {"model": "mirror"}},
        {"name": "wide", "brdf": {"model": "ward", "alpha_x": 0.05, "alpha_y": 0.01}},
    ]
    d["output"] = {"figures": True}
    cfg = parse_config(d)
    calls = []
    result = pipeline.run_simulation(cfg, tmp_path / "cmp", lambda a, b: calls.append((a, b)))
    out = result.outdir
    assert calls[-1][0] == calls[-1][1]
    assert [r.config.name for r in result.variants] == ["mirror", "wide"]
    assert result.dataset_path is None and (out / "figures" / "fringes_variants.png").is_file()
    for name in ("mirror", "wide"):
        assert is_run_dir(out / name) and (out / name / "fringes" / "x_w008_k0.tif").is_file()
    assert result.rays_traced == result.surface_pixels * (1 + 10)

    combined = schema.load_run(out)
    assert combined["fringes"].dims == ("variant", "direction", "width", "shift", "row", "col")
    assert [str(v) for v in combined["variant"].values] == ["mirror", "wide"]
    assert combined["surface_mask"].dims == ("row", "col")
    assert schema.run_config(combined) == cfg
    # Each sub-run is reproducible on its own from its stored configuration.
    wide = schema.load_run(out, variant="wide")
    wide_cfg = schema.run_config(wide)
    assert wide_cfg.variants == () and wide_cfg.brdf.alpha_x == 0.05
    alone = pipeline.run_simulation(wide_cfg, tmp_path / "alone", figures=False)
    np.testing.assert_array_equal(schema.load_run(alone.outdir)["fringes"].values,
                                  wide["fringes"].values)
    np.testing.assert_array_equal(combined["fringes"].sel(variant="wide").values,
                                  wide["fringes"].values)
    # The mirror: full modulation, values = monitor luminance at the specular point.
    mirror = schema.load_run(out, variant="mirror")
    mod = np.hypot(mirror["fringe_sums_real"], mirror["fringe_sums_imag"]) / mirror["f_hit"]
    np.testing.assert_allclose(np.nanmin(mod.values), 1.0, rtol=4 * 2.0 ** -KEEP_BITS)


@pytest.mark.parametrize("name", ["..", "figures", "config.json"])
def test_variant_names_that_would_escape_are_refused(tmp_path, name):
    d = tiny_config_dict()
    d["variants"] = [{"name": name, "brdf": {"model": "mirror"}}]
    with pytest.raises(ValueError, match="variants.0.name"):
        pipeline.run_simulation(parse_config(d), tmp_path / "run")
    assert list(tmp_path.iterdir()) == []


def test_fringes_off_dots_only(tmp_path):
    d = tiny_config_dict(fringes=False, dots={"size_px": 9, "positions_px": [[80, 45]]})
    result = pipeline.run_simulation(parse_config(d), tmp_path / "dots", figures=True)
    assert [p.name for p in result.image_paths] == ["dot000_u0080_v0045.tif"]
    assert [p.name for p in result.figure_paths] == ["setup.png", "dot_contact_sheet.png",
                                                     "dot_shapes.png"]
    ds = schema.load_run(result.outdir)
    assert "fringes" not in ds and ds["dots"].shape == (1, 40, 48)


def test_load_run_missing(tmp_path):
    with pytest.raises(FileNotFoundError):
        schema.load_run(tmp_path / "nothing")


# ----------------------------------------------------------------------------- CLI
def _invoke(args):
    from typer.testing import CliRunner

    from pmdsim.cli import app

    result = CliRunner().invoke(app, args)
    return result, result.output


def test_cli_help_and_version():
    result, text = _invoke(["--help"])
    assert result.exit_code == 0 and "simulate" in text and "version" in text
    result, text = _invoke(["simulate", "--help"])
    assert result.exit_code == 0 and "--overwrite" in text and "--no-figures" in text
    result, text = _invoke(["version"])
    assert result.exit_code == 0 and "pmdsim" in text


def test_cli_simulate_tiny(tmp_path):
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TOML.format(pitch_key="pixel_pitch_mm"))
    out = tmp_path / "out"
    result, text = _invoke(["simulate", str(cfg), "-o", str(out), "--no-figures"])
    assert result.exit_code == 0, text
    assert is_run_dir(out) and not (out / "figures").exists()
    assert "rays per pixel" in text and "run folder" in text
    # A second run without --overwrite is refused with exit code 2, the run stays.
    result, text = _invoke(["simulate", str(cfg), "-o", str(out), "--no-figures"])
    assert result.exit_code == 2 and "--overwrite" in text and "Traceback" not in text
    result, text = _invoke(["simulate", str(cfg), "-o", str(out), "--no-figures",
                            "--overwrite"])
    assert result.exit_code == 0, text


def test_cli_config_typo_exit_code_2(tmp_path):
    cfg = tmp_path / "typo.toml"
    cfg.write_text(TOML.format(pitch_key="pixel_pich_mm"))
    result, text = _invoke(["simulate", str(cfg), "-o", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert "monitor.pixel_pich_mm" in text and "Traceback" not in text
    assert not (tmp_path / "out").exists()
    result, text = _invoke(["simulate", str(tmp_path / "missing.toml"), "-o",
                            str(tmp_path / "out")])
    assert result.exit_code == 2 and "missing.toml" in text



# ----------------------------------------------------------------------------- diagnostics
def _toml_with(widths: str = "[8.0]", extra: str = "") -> str:
    return TOML.format(pitch_key="pixel_pitch_mm").replace("widths_px = [8.0]",
                                                           f"widths_px = {widths}") + extra


def test_cli_simulate_prints_diagnostics_warnings(tmp_path):
    """The paper's 1 deg cone on the Fig. 3 lobe (alpha_x = 0.025): simulate warns after the
    summary table, in yellow, naming the setting that fixes each warning, and stores the maps,
    the summary and the warnings in the run."""
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(_toml_with())
    out = tmp_path / "out"
    result, text = _invoke(["simulate", str(cfg), "-o", str(out), "--no-figures"])
    assert result.exit_code == 0, text
    assert "warning: theta_max = 1 deg holds 37 % of the lobe energy" in text
    assert "theta_max >= 4 deg keeps 95 %" in text
    assert "[setting: sampling.theta_max_deg = 4]" in text
    assert "raise sampling.n_rays to ~" in text  # phase standard error (seeds method) > 1 mrad
    assert text.index("warning:") > text.index("run folder")  # after the summary table
    assert "lobe energy inside theta_max 37.5 %" in text  # summary-table row

    stats = json.loads((out / "statistics.json").read_text())["diagnostics"]
    assert stats["phase_se_method"] == "seeds" and stats["grid"] == {"columns": 24, "rows": 20}
    # derived by deterministic quadrature for this scene (tests/naive_lobe.py), not copied
    # from a run: 37.5 % inside 1 deg, 3.97 deg for 95 %
    import naive_lobe
    from pmdsim.config import load_config
    from pmdsim.studies.diagnostics import PixelGrid

    grid = PixelGrid.spread((40, 48), 24, 20)
    frac, theta, _ = naive_lobe.fig3_numbers(load_config(cfg), grid.pixel_rows, grid.pixel_cols)
    assert stats["energy"]["fraction_median"] == pytest.approx(frac, abs=2e-3)
    assert stats["energy"]["theta_needed_deg_max"] == pytest.approx(theta, abs=0.01)
    codes = {w["code"]: w for w in stats["warnings"]}
    assert codes["energy_fraction"]["setting"] == "sampling.theta_max_deg"
    assert codes["energy_fraction"]["suggested"] == 4.0
    assert codes["phase_error"]["setting"] == "sampling.n_rays"
    summary = (out / "summary.txt").read_text()
    assert "pmdsim run diagnostics" in summary and "[setting: sampling.theta_max_deg = 4]" in summary
    manifest = json.loads((out / MANIFEST).read_text())
    assert len(manifest["warnings"]) == len(stats["warnings"])

    ds = schema.load_run(out)
    assert ds["diag_energy_fraction"].dims == ("diag_row", "diag_col")
    assert ds["diag_phase_se"].dims == ("direction", "width", "diag_row", "diag_col")
    assert ds["diag_effective_sample_size"].attrs["units"] == "rays"
    frac = ds["diag_energy_fraction"].values
    assert np.nanmedian(frac) == pytest.approx(stats["energy"]["fraction_median"])
    assert np.isnan(frac).any() and np.isfinite(frac).any()  # the camera sees past the plate
    assert int(ds["diag_col"][-1]) == 47 and int(ds["diag_row"][-1]) == 39


def test_cli_simulate_warnings_follow_the_diagnostics_bounds(tmp_path):
    """The same scene warns with the default [diagnostics] bounds and is quiet with relaxed
    ones; the bounds' grid sets the diagnostics grid."""
    out = tmp_path / "strict"
    strict = tmp_path / "strict.toml"
    strict.write_text(_toml_with("[64.0]"))
    result, text = _invoke(["simulate", str(strict), "-o", str(out), "--no-figures"])
    assert result.exit_code == 0, text
    assert "warning: theta_max = 1 deg" in text and "sampling.theta_max_deg" in text
    assert "raise sampling.n_rays" in text

    relaxed = tmp_path / "relaxed.toml"
    relaxed.write_text(_toml_with("[64.0]", "\n[diagnostics]\nmin_energy_fraction = 0.3\n"
                                  "max_phase_error_mrad = 1000.0\nmin_ess_fraction = 0.2\n"
                                  "grid = [6, 5]\n"))
    out = tmp_path / "relaxed"
    result, text = _invoke(["simulate", str(relaxed), "-o", str(out), "--no-figures"])
    assert result.exit_code == 0, text
    assert "warning:" not in text and "diagnostics" in text
    stats = json.loads((out / "statistics.json").read_text())["diagnostics"]
    assert stats["warnings"] == [] and stats["grid"] == {"columns": 6, "rows": 5}
    assert stats["bounds"]["max_phase_error_mrad"] == 1000.0
    assert "no warnings" in (out / "summary.txt").read_text()
    ds = schema.load_run(out)
    assert ds.sizes["diag_row"] == 5 and ds.sizes["diag_col"] == 6


def test_cli_simulate_no_diagnostics(tmp_path):
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(_toml_with())
    out = tmp_path / "out"
    result, text = _invoke(["simulate", str(cfg), "-o", str(out), "--no-figures",
                            "--no-diagnostics"])
    assert result.exit_code == 0, text
    assert "warning:" not in text and "lobe energy" not in text
    assert not (out / "statistics.json").exists()  # nothing decoded, no diagnostics
    assert not [v for v in schema.load_run(out).data_vars if str(v).startswith("diag_")]
    assert json.loads((out / MANIFEST).read_text())["warnings"] == []


def test_diagnostics_of_variants(tmp_path):
    """Per variant: none for the mirror, no energy fraction for the radiometric estimator
    (it has no cone); load_run fills the mirror's maps with NaN; the CLI names the variant."""
    d = tiny_config_dict()
    d["variants"] = [
        {"name": "mirror", "brdf": {"model": "mirror"}},
        {"name": "radiometric", "sampling": {"n_rays": 16, "estimator": "radiometric", "mode": "stratified"}},
        {"name": "paper"},
    ]
    d["diagnostics"] = {"grid": [8, 6]}
    result = pipeline.run_simulation(parse_config(d), tmp_path / "cmp")
    subs = {r.config.name: r for r in result.variants}
    assert subs["mirror"].warnings == () and "diagnostics" not in subs["mirror"].statistics
    rad = subs["radiometric"].statistics["diagnostics"]
    assert "energy" not in rad and rad["ess_median"] > 12
    assert not [w for w in subs["radiometric"].warnings if w.code == "energy_fraction"]
    assert [w.code for w in subs["paper"].warnings][0] == "energy_fraction"
    top = json.loads((result.outdir / "statistics.json").read_text())["variants"]
    assert set(top) == {"radiometric", "paper"}
    assert "pmdsim run diagnostics: paper" in (result.outdir / "summary.txt").read_text()
    ds = schema.load_run(result.outdir)
    assert ds["diag_effective_sample_size"].dims == ("variant", "diag_row", "diag_col")
    assert np.isnan(ds["diag_effective_sample_size"].sel(variant="mirror").values).all()
    assert np.isnan(ds["diag_energy_fraction"].sel(variant="radiometric").values).all()
    paper = ds["diag_energy_fraction"].sel(variant="paper").values
    assert 0.3 < np.nanmedian(paper) < 0.45
    manifest = json.loads((result.outdir / MANIFEST).read_text())
    assert manifest["warnings"]["mirror"] == [] and manifest["warnings"]["paper"]
