"""Run figures: the default summary, pmdsim report re-drawing any figure from a run folder,
and the thinned imshow drawing the same picture as matplotlib's own nearest resampling."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from typer.testing import CliRunner

from pmdsim import run as pipeline

from pmdsim.store import schema
from pmdsim.cli import app
from pmdsim.config import parse_config
from pmdsim.report.scene import MAX_IMAGE_PX, imshow
from test_pipeline import tiny_config_dict
from conftest import base_dict
from pmdsim.report.chain_maps import plot_deviation, plot_histograms
from pmdsim.report.overview import plot_overview, plot_variant_deviation


def _pixels(draw) -> np.ndarray:
    fig = Figure(figsize=(4.0, 3.0), dpi=130)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.1, 0.1, 0.85, 0.85))
    draw(ax)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].astype(int)


def test_thinned_image_draws_like_matplotlib_nearest():
    h, w = 1000, 1400  # thinned by 3 (> MAX_IMAGE_PX)
    assert -(-max(h, w) // MAX_IMAGE_PX) == 3
    r, c = np.mgrid[0:h, 0:w]
    image = np.sin(c / 90.0) * np.cos(r / 70.0) + r / h  # smooth at the panel's resolution
    image[400:600, 500:900] = np.nan  # a masked block stays where it is
    full = _pixels(lambda ax: ax.imshow(image, cmap="viridis", interpolation="nearest"))
    thin = _pixels(lambda ax: imshow(ax, image, cmap="viridis", interpolation="nearest"))
    diff = np.abs(full - thin).max(axis=-1)
    assert np.mean(diff <= 12) > 0.98, np.mean(diff <= 12)
    fig = Figure()
    ax = fig.add_subplot()
    imshow(ax, image)
    assert ax.get_xlim() == (-0.5, w - 0.5) and ax.get_ylim() == (h - 0.5, -0.5)


@pytest.fixture(scope="module")
def decoded_run(tmp_path_factory):
    d = tiny_config_dict(fringes={"widths_px": [10, 40, 160], "shifts": 4})
    d["output"] = {"figures": True, "write_images": False}
    out = tmp_path_factory.mktemp("figures") / "run"
    return pipeline.run_simulation(parse_config(d), out)


def test_default_figures_are_the_summary(decoded_run):
    # the summary: set-up, overview and (the run reconstructs the surface) its errors
    assert sorted(p.name for p in (decoded_run.outdir / "figures").iterdir()) == [
        "overview.png", "setup.png", "surface_errors.png", "surface_psd.png"]


def test_report_redraws_any_figure_from_the_run_folder(decoded_run, tmp_path):
    runner = CliRunner()
    res = runner.invoke(app, ["report", str(decoded_run.outdir), "--figure", "deviation",
                              "--figure", "setup", "-o", str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["deviation.png", "setup.png"]
    res = runner.invoke(app, ["report", str(decoded_run.outdir), "--all", "--workers", "1",
                              "-o", str(tmp_path / "b")])
    assert res.exit_code == 0, res.output
    assert len(list((tmp_path / "b").iterdir())) == 11
    bad = runner.invoke(app, ["report", str(decoded_run.outdir), "--figure", "nonsense"])
    assert bad.exit_code == 2 and "unknown figure" in bad.output
    missing = runner.invoke(app, ["report", str(tmp_path)])
    assert missing.exit_code == 2 and "no run.zarr" in missing.output


@pytest.mark.skipif(not __import__("pmdsim.run.figures", fromlist=["can_fork"]).can_fork(),
                    reason="forked drawing is Linux only")
def test_forked_drawing_draws_the_same_picture_as_in_process(decoded_run, tmp_path):
    """A run draws its figures in forked processes from its in-memory data; the pixels are
    those of the same figure drawn in the process itself (nothing lost on the way)."""
    from PIL import Image

    from pmdsim.run.figures import Drawing, _simulation

    ds = schema.load_run(decoded_run.outdir).load()
    sim = _simulation(ds)
    names = ["overview", "setup"]
    forked = Drawing(names, tmp_path / "forked", "tiny", "", ds, sim, fork=True)
    assert forked.proc is not None
    here = Drawing(names, tmp_path / "here", "tiny", "", ds, sim, fork=False)
    notes: list = []
    a, b = forked.paths(notes), here.paths(notes)
    assert notes == [] and [p.name for p in a] == [p.name for p in b] == [
        "overview.png", "setup.png"]
    for p, q in zip(a, b):
        np.testing.assert_array_equal(np.asarray(Image.open(p)), np.asarray(Image.open(q)))
    assert forked.proc is None  # the process was joined


def test_a_figure_that_fails_in_a_drawing_process_is_a_note(tmp_path, monkeypatch):
    """A figure that cannot be drawn (here: the overview raises) is a note of the run; the
    other figures and all the data are written."""

    def boom(*args, **kwargs):
        raise ValueError("no overview today")

    from pmdsim.report import overview

    monkeypatch.setattr(overview, "plot_overview", boom)
    d = tiny_config_dict(fringes={"widths_px": [10, 40, 160], "shifts": 4})
    d["output"] = {"figures": True, "write_images": True}
    d["reconstruct"] = {"enabled": False}
    res = pipeline.run_simulation(parse_config(d), tmp_path / "run")
    assert [p.name for p in res.figure_paths] == ["setup.png"]
    assert any("figure overview could not be drawn" in n and "no overview today" in n
               for n in res.notes), res.notes
    assert (res.outdir / "run.zarr").is_dir() and len(res.image_paths) == 2 * 3 * 4
    assert sorted(p.name for p in (res.outdir / "figures").iterdir()) == ["setup.png"]


def test_a_failed_fork_draws_in_the_run_process(decoded_run, tmp_path, monkeypatch):
    """Where fork fails (strict memory overcommit: ENOMEM) the figures are drawn by the run
    itself when it asks for them; the run does not fail."""
    import os

    from pmdsim.run.figures import Drawing, _simulation

    def no_fork():
        raise OSError(12, "Cannot allocate memory")

    ds = schema.load_run(decoded_run.outdir).load()
    monkeypatch.setattr(os, "fork", no_fork)
    d = Drawing(["surface_errors"], tmp_path, "tiny", "", ds, _simulation(ds), fork=True)
    assert d.proc is None
    notes: list = []
    assert [p.name for p in d.paths(notes)] == ["surface_errors.png"] and notes == []


def test_the_chain_figures_start_before_the_reconstruction(tmp_path, monkeypatch):
    """The overview needs only the chain: its drawing starts before the surface is
    reconstructed, the reconstruction's figure right after the reconstruction; the
    diagnostics start right after the render (a thread beside the chain), before any
    figure; the run's statistics still hold the reconstruction and the diagnostics, and a
    run without decoding draws its figures too."""
    import json

    from pmdsim.run import figures as figures_mod
    from pmdsim.run import steps as member_mod
    from pmdsim.run import reconstruction as recon

    events = []
    start, from_chain, diagnose = (figures_mod.start_drawings, recon.from_chain,
                                   member_mod.diagnose_run)

    def start_drawings(names, *args, **kwargs):
        events.append(("figures", tuple(names)))
        return start(names, *args, **kwargs)

    def record(tag, fn):
        def wrapped(*args, **kwargs):
            events.append((tag,))
            return fn(*args, **kwargs)
        return wrapped

    monkeypatch.setattr(figures_mod, "start_drawings", start_drawings)
    monkeypatch.setattr(recon, "from_chain", record("reconstruction", from_chain))
    monkeypatch.setattr(member_mod, "diagnose_run", record("diagnostics", diagnose))
    d = tiny_config_dict(fringes={"widths_px": [10, 40, 160], "shifts": 4})
    d["output"] = {"figures": True, "write_images": False}
    res = pipeline.run_simulation(parse_config(d), tmp_path / "run")
    drawn = [e for e in events if e[0] == "figures" and e[1]]
    # the set-up figure (its data exist after the render) is drawn with the overview: one
    # fork of the run's process fewer
    assert events.index(("diagnostics",)) < events.index(("figures", ("setup", "overview"))) \
        < events.index(("reconstruction",)) \
        < events.index(("figures", ("surface_errors", "surface_psd")))
    assert [e[1] for e in drawn] == [("setup", "overview"), ("surface_errors", "surface_psd")]
    stats = json.loads((res.outdir / "statistics.json").read_text())
    assert "reconstruction" in stats and "diagnostics" in stats
    assert json.loads(schema.load_run(res.outdir).attrs["statistics_json"]) == stats
    assert sorted(p.name for p in res.figure_paths) == [
        "overview.png", "setup.png", "surface_errors.png", "surface_psd.png"]

    d["decode"] = {"enabled": False}  # no chain: the fringe figures only
    res = pipeline.run_simulation(parse_config(d), tmp_path / "plain")
    assert sorted(p.name for p in res.figure_paths) == [
        "fringes.png", "modulation.png", "setup.png"]


# ------------------------------------------------------------------ readable figures
def _axis_problems(ax, which: str) -> list[str]:
    """What an axis of a drawn axes lacks: a label, or at least two labelled ticks."""
    axis = getattr(ax, f"{which}axis")
    out = []
    if not axis.get_label_text().strip():
        out.append(f"no {which} label")
    shown = [t.get_text() for t in axis.get_ticklabels() if t.get_visible() and t.get_text()]
    if len(shown) < 2:
        out.append(f"{which}: {len(shown)} labelled ticks")
    return out


def figure_problems(fig) -> list[str]:
    """Every visible axes of a drawn figure has labelled ticks: a map or a plot both its x and
    y axis (label and at least two tick labels), a colour bar its long axis. Axes switched
    off (legend panels, text boxes) carry no data and are skipped."""
    problems = []
    for ax in fig.axes:
        if not ax.axison or not ax.get_visible():
            continue
        name = ax.get_title().split("\n")[0] or ax.get_label() or "?"
        colorbar = getattr(ax, "_colorbar", None)
        if colorbar is not None:
            which = ["x" if colorbar.orientation == "horizontal" else "y"]
        else:
            which = ["x", "y"] + (["z"] if hasattr(ax, "zaxis") else [])
        problems += [f"{name!r}: {p}" for w in which for p in _axis_problems(ax, w)]
    return problems


@pytest.fixture
def recorded(monkeypatch):
    """{file name: problems} of every figure saved while the fixture is active (checked
    right after it is drawn, before anything closes it)."""
    seen: dict = {}
    save = Figure.savefig

    def savefig(self, fname, *args, **kwargs):
        save(self, fname, *args, **kwargs)
        from pathlib import Path

        seen[Path(fname).name] = figure_problems(self)

    monkeypatch.setattr(Figure, "savefig", savefig)
    return seen


def test_every_run_figure_has_labelled_axes(decoded_run, tmp_path, recorded):
    from pmdsim.report.scene import plot_variant_fringes
    from pmdsim.run.figures import FIGURES, _simulation, draw_one

    ds = schema.load_run(decoded_run.outdir).load()
    sim = _simulation(ds)
    for name in FIGURES:  # every figure a run draws (pmdsim report --all)
        draw_one(ds, name, tmp_path, "tiny", "a tiny run", sim=sim)
    both = {"a": ds, "b": ds}  # the variants' comparison figures
    plot_variant_deviation(both, tmp_path / "deviation_variants.png")
    plot_variant_fringes(both, tmp_path / "fringes_variants.png")
    expected = {f for f, _ in FIGURES.values()} | {"deviation_variants.png",
                                                   "fringes_variants.png"}
    assert set(recorded) == expected
    bad = {k: v for k, v in recorded.items() if v}
    assert not bad, bad


def test_decoded_image_set_figures_have_labelled_axes_and_distinct_flag_colours(tmp_path, recorded):
    """``pmdsim decode``'s maps, on frames with flagged pixels (no fringes, NaN)."""
    import tifffile
    from matplotlib.colors import to_rgb

    from pmdsim.report.chain_common import FLAG_COLOURS
    from pmdsim.run.decode_run import decode_files, make_setup

    widths, k = [10.0, 40.0, 160.0], 4
    rows, cols = np.mgrid[0:40, 0:56]
    u = 1.0 + 2.7 * cols + 0.3 * rows  # monitor px seen by each camera pixel
    paths = []
    for w in widths:
        for s in range(k):
            img = 0.5 + 0.4 * np.cos(2 * np.pi * u / w + 2 * np.pi * s / k)
            img[:8, :8] = 0.5  # no fringes: LOW_AMPLITUDE
            img[20, 20] = np.nan  # NAN_INPUT
            paths.append(tmp_path / f"f_{len(paths):02d}.tif")
            tifffile.imwrite(paths[-1], img.astype(np.float32))
    setup = make_setup(widths=widths, shifts=k, direction="x", extent_px=160.0)
    decode_files(paths, tmp_path / "out", setup)
    assert {"absolute_phase.png", "monitor_coord.png", "modulation.png", "flags.png"} <= set(recorded)
    bad = {k: v for k, v in recorded.items() if v}
    assert not bad, bad
    rgb = np.array([to_rgb(c) for c in FLAG_COLOURS.values()])
    dist = np.linalg.norm(rgb[:, None] - rgb[None], axis=-1)[np.triu_indices(len(rgb), 1)]
    assert dist.min() > 0.3, dist.min()  # no two flags in colours that cannot be told apart


def test_problems_are_found():
    # the checker itself: a map without ticks and a colour bar without a label are reported
    fig = Figure()
    ax = fig.add_subplot()
    im = ax.imshow(np.arange(12.0).reshape(3, 4))
    ax.set_xticks([])
    ax.set_xlabel("camera column (px)")
    fig.colorbar(im, ax=ax)
    FigureCanvasAgg(fig).draw()
    found = figure_problems(fig)
    assert any("x: 0 labelled ticks" in p for p in found)
    assert any("no y label" in p for p in found)
    assert sum("no y label" in p for p in found) == 2  # the map's and the colour bar's


def test_dot_shape_figure_has_labelled_axes(tmp_path, recorded):
    """The dot scan's shapes (maps and the orientation plot). The contact sheet's crops are
    thumbnails whose size its title states; they carry no ticks by design."""
    from types import SimpleNamespace

    from pmdsim.measure.chain import dot_table
    from pmdsim.report.dots import plot_dot_shapes

    rows, cols = np.mgrid[0:40, 0:56]
    dots, images = [], []
    for k, (u, v) in enumerate([(60, 60), (300, 60), (60, 200), (300, 200)]):
        c, r = 10 + 30 * (k % 2), 10 + 18 * (k // 2)
        images.append(np.exp(-0.5 * ((cols - c) ** 2 / (1.5 + k) ** 2 + (rows - r) ** 2 / 1.2 ** 2)))
        dots.append(SimpleNamespace(u=u, v=v, size=15))
    images = np.array(images)
    table = dot_table(images, dots, "a")
    plot_dot_shapes({"a": images}, {"a": table}, tmp_path / "dot_shapes.png", centre_px=(27.5, 19.5))
    assert recorded == {"dot_shapes.png": []}


def test_deviation_figures_print_value_pm_numerical_error(decoded_run, tmp_path, monkeypatch):
    """Issue 18: every RMS/P95 a deviation figure prints (titles, histogram legends) carries
    the run's numerical error of that statistic as "value ± error" where the run states one
    (the coordinate against the exact point: the decoded coordinate's error); the tiny run
    renders the lattice (no error), so its statistics get one here."""
    import json
    import re


    ds = schema.load_run(decoded_run.outdir).load()
    st = json.loads(ds.attrs["statistics_json"])
    errors = {}
    for i, (d, s) in enumerate(st["directions"].items()):
        errors[d] = {q: {"rms": 0.0123 + i, "p95": 0.0456 + i, "max": 0.1}
                     for q in ("phase_mrad", "coord_px", "coord_mm", "slope_urad")}
        s["numerical_error"] = errors[d]
    ds.attrs["statistics_json"] = json.dumps(st)
    texts: dict = {}
    save = Figure.savefig

    def savefig(self, fname, *args, **kwargs):
        from pathlib import Path

        found = [self._suptitle.get_text()] if self._suptitle else []
        for ax in self.axes:
            found.append(ax.get_title())
            leg = ax.get_legend()
            found += [t.get_text() for t in leg.get_texts()] if leg else []
        texts[Path(fname).name] = found
        save(self, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", savefig)
    plot_overview(ds, tmp_path / "overview.png")
    plot_deviation(ds, tmp_path / "deviation.png")
    plot_histograms(ds, tmp_path / "histograms.png")
    plot_variant_deviation({"a": ds}, tmp_path / "deviation_variants.png")
    assert set(texts) == {"overview.png", "deviation.png", "histograms.png", "deviation_variants.png"}
    printed = 0
    for name, found in texts.items():
        for t in found:
            for stat, value in re.findall(r"(RMS|P95) ([-+0-9.e]+)", t):
                printed += 1
                assert re.search(rf"{stat} {re.escape(value)} ± \S+", t), (name, t)
    assert printed >= 20
    # the numbers are the statistics' own: X's phase RMS and its error in the deviation map
    x = st["directions"]["x"]
    dev = " ".join(texts["deviation.png"])
    assert f"RMS {x['phase_mrad']['rms']:.3g} ± 0.012 mrad" in dev or \
        f"RMS {x['phase_mrad']['rms']:.3g} ± 0.012," in dev


def test_numerical_warnings_name_every_printed_deviation_over_10_percent():
    from pmdsim.report.text import numerical_warnings

    def stats(err_coord):
        dev = {"phase_mrad": {"rms": 1.0, "p95": 2.0}, "coord_px": {"rms": 0.01, "p95": 0.02},
               "coord_mm": {"rms": 0.0025, "p95": 0.005}, "slope_urad": {"rms": 3.0, "p95": 6.0},
               "coord_vs_exact_px": {"rms": 0.001, "p95": 0.002}}
        ne = {"phase_mrad": {"rms": 0.05, "p95": 0.1}, "coord_px": {"rms": err_coord, "p95": err_coord},
              "coord_mm": {"rms": 1e-5, "p95": 1e-5}, "slope_urad": {"rms": 0.2, "p95": 0.4}}
        return {"directions": {"x": {**dev, "numerical_error": ne}, "y": dict(dev)}}

    assert numerical_warnings(stats(5e-5)) == []  # every error below 10 % (y states none)
    # 5e-4 px: 5 % of the coordinate vs the mirror, 50 % of the one vs the exact point
    (w,) = numerical_warnings(stats(5e-4))
    assert w.startswith("x: ") and "coord_vs_exact_px rms 0.001 ± 0.0005" in w
    assert "coord_vs_exact_px p95 0.002 ± 0.0005" in w and "coord_px rms" not in w
    (w,) = numerical_warnings(stats(2e-3))  # now over 10 % of both coordinates
    assert "coord_px rms 0.01 ± 0.002" in w and "phase_mrad" not in w


def test_setup_figure_draws_the_rule_a_target_picked(tmp_path, monkeypatch):
    """With a target the pilot picks the rule after the figure schedule was made: the
    set-up figure (its bundle of rays) is drawn with the rule rendered, in the run and when
    re-drawn from the run folder, not with n_rays, the pilot's start."""
    import json

    from pmdsim.run import figures as figures_mod

    given = {}
    start = figures_mod.start_drawings

    def start_drawings(names, folder, run_name, description, ds, sim, *args, **kwargs):
        for n in names:
            given[n] = sim
        return start(names, folder, run_name, description, ds, sim, *args, **kwargs)

    monkeypatch.setattr(figures_mod, "start_drawings", start_drawings)
    from test_quadrature import fig3  # the Fig. 3 example on a 40 x 32 camera

    d = fig3(n_rays=16, target_error_mrad=0.1)
    d["output"] = {"figures": True, "write_images": False}
    res = pipeline.run_simulation(parse_config(d), tmp_path / "run")
    picked = json.loads((res.outdir / "statistics.json").read_text())["sampling"]["n_rays"]
    assert picked > 16
    assert given["setup"].scene.sampling.n_rays == picked
    ds = schema.load_run(res.outdir)
    again = figures_mod._simulation(ds)
    assert again.scene.sampling.n_rays == picked
    assert again.scene.rays_per_pixel == ds.attrs["rays_per_pixel"]


@pytest.mark.parametrize("mode", ["rule", "stratified"])
def test_setup_footprint_marks_p_at_the_specular_point(tmp_path, monkeypatch, mode):
    """The set-up figure's "+" marks P, the pixel's specular direction, where it meets the
    monitor: the render's geometry (``specular_u``, ``specular_v``) at that pixel. A Gauss
    rule's nodes do not include P (ray 0 is its first node, several monitor px away on
    Fig. 3); only the paper's stratified set starts with it."""
    import numpy as np

    from pmdsim.render import Simulation
    from pmdsim.report import scene as plot

    figs = []
    monkeypatch.setattr(plot, "_save", lambda fig, path, dpi=None: figs.append(fig) or path)
    d = base_dict()
    d["sampling"] = {"mode": mode, "n_rays": 96, "theta_max_deg": 2.0}
    sim = Simulation.from_config(parse_config(d))
    pixel = (15, 20)
    plot.plot_setup(sim, tmp_path / "setup.png", pixel=pixel)
    geo = sim.geometry()
    marks = [c for ax in figs[0].axes for c in ax.collections
             if str(c.get_label()).startswith("P ")]
    assert len(marks) == 1
    np.testing.assert_allclose(marks[0].get_offsets()[0],
                               [geo.specular_u[pixel], geo.specular_v[pixel]], atol=1e-9)
    u, v, _, _, _ = sim.transport([pixel[0]], [pixel[1]], directions=False)
    first = np.hypot(u[0, 0] - geo.specular_u[pixel], v[0, 0] - geo.specular_v[pixel])
    assert (first > 0.05) if mode == "rule" else (first < 1e-9)  # ray 0 is P only there


def test_log_tick_labels_are_powers_of_ten_in_plain_text():
    """The PSD figures' log axes label 10^k as "10" and a superscript k (no mathtext), read
    back to the value they stand for; other values as %g; nothing at 0 or below."""
    from matplotlib.ticker import LogLocator

    from pmdsim.report.psd import log_ticks, power_label

    digits = str.maketrans("⁻⁰¹²³⁴⁵⁶⁷⁸⁹", "-0123456789")
    for k in range(-15, 16):
        label = power_label(10.0 ** k)
        assert label.startswith("10") and "$" not in label
        assert float("1e" + label[2:].translate(digits)) == pytest.approx(10.0 ** k, rel=1e-12)
    assert power_label(2e-3) == "0.002" and power_label(50.0) == "50"
    assert power_label(0.0) == "" and power_label(-1.0) == ""
    fig = Figure(figsize=(3.0, 3.0))
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.2, 0.2, 0.7, 0.7))
    ax.set_yscale("log")
    ax.set_ylim(1e-7, 1e5)
    ax.yaxis.set_major_locator(LogLocator(numticks=20))
    log_ticks(ax.yaxis)
    fig.canvas.draw()
    shown = [t.get_text() for t in ax.yaxis.get_ticklabels() if t.get_text()]
    assert "10⁻⁷" in shown and "10⁵" in shown and "10⁰" in shown
    assert not ax.yaxis.get_minor_ticks()


def test_histogram_counts_are_those_of_the_linspace_edges():
    """The deviation histogram bins by NumPy's uniform path (bins and range): the counts of
    the explicit edges linspace(-lim, lim, bins + 1), values on the edges and the clipped
    tails (the end bins) included."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pmdsim.report.chain_common import _histogram

    rng = np.random.default_rng(4)
    lim, bins = 0.3, 121
    edges = np.linspace(-lim, lim, bins + 1)
    a = np.concatenate([rng.normal(0.02, 0.1, 50_000), edges, edges[::7] + 1e-17,
                        [-5.0, 7.0, np.nan]])
    fig, ax = plt.subplots()
    _histogram(ax, {"X": a}, {"X": "C0"}, {}, bins=bins, lim=lim)
    drawn = ax.patches[0].get_xy()  # the step outline: (x, height) of every bin
    plt.close(fig)
    want, _ = np.histogram(np.clip(a[np.isfinite(a)], -lim, lim), bins=edges)
    heights = drawn[1:-1:2, 1]  # each bin's top-left and top-right corner hold its count
    np.testing.assert_array_equal(heights, want)


def test_figures_held_for_the_chain_start_at_the_end_when_it_never_comes(monkeypatch):
    """In a decoding run the set-up figure waits for the chain's figures (one fork fewer);
    a run whose chain figures never come draws it when the run collects its figures; a run
    without decoding draws it at once."""
    import xarray as xr

    from pmdsim.run import figures as figures_mod

    started = []
    monkeypatch.setattr(figures_mod, "start_drawings",
                        lambda names, *a, **k: started.append(tuple(names)) or [])
    images = xr.Dataset({"fringes": (("row", "col"), np.zeros((2, 3)))})
    chain = images.assign(phase_deviation=(("row", "col"), np.zeros((2, 3))))

    sched = figures_mod.FigureSchedule("summary", True, Path("."), "r", "", sim=None)
    assert sched.offer(images) == [] and started == []
    assert sched.offer(chain) == ["setup", "overview"]
    assert started == [("setup", "overview")]

    started.clear()
    sched = figures_mod.FigureSchedule("summary", True, Path("."), "r", "", sim=None)
    sched.offer(images)
    assert started == []
    assert sched.paths([]) == [] and started == [("setup",)]

    started.clear()
    sched = figures_mod.FigureSchedule("summary", False, Path("."), "r", "", sim=None)
    assert sched.offer(images) == ["setup", "fringes", "modulation"]


def _compile_a_new_kernel() -> None:
    from numba import njit

    @njit(cache=False)
    def twice(x):
        return 2.0 * x

    assert twice(1.5) == 3.0


def test_a_figure_fork_waits_for_a_compiling_thread_and_the_child_compiles():
    """No fork while another thread compiles or loads a kernel (Numba's compiler lock,
    whose LLVM lock a forked process would inherit taken and hang on); the forked process
    itself compiles (the lock it inherits is its own thread's, re-entrant)."""
    import multiprocessing as mp
    import threading
    import time

    from numba.core.compiler_lock import global_compiler_lock

    from pmdsim.run.figures import _no_compilation

    held, order = threading.Event(), []

    def compiling():
        with global_compiler_lock:
            held.set()
            time.sleep(0.3)
            order.append("compiled")

    t = threading.Thread(target=compiling)
    t.start()
    held.wait()
    with _no_compilation():
        order.append("fork")
        child = mp.get_context("fork").Process(target=_compile_a_new_kernel)
        child.start()
    child.join(timeout=120)
    t.join()
    assert order == ["compiled", "fork"]
    assert child.exitcode == 0
