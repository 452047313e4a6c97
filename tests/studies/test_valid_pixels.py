"""Nothing exits 0 with 0 % valid pixels unless asked; the message names the stage that
removed them and its share (pmdsim.studies.valid_pixels)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import make_config
from pmdsim.studies.valid_pixels import check_valid, removed_by_stage

WIDE = {"brdf": {"alpha_x": 1.0, "alpha_y": 1.0},
        "sampling": {"estimator": "radiometric", "n_rays": 32},
        "patterns": {"fringes": {"widths_px": [10.0, 40.0, 200.0]}}}


def test_the_stage_counts_add_up_to_the_camera_pixels():
    px = {"surface": 900, "considered": 700, "valid": 100, "low_modulation": 50,
          "decode_flagged": 120, "lobe_off_monitor": 430, "reference_flagged_on_surface": 200,
          "decode_flags_of_considered": {"SATURATED": 20, "LOW_AMPLITUDE": 100}}
    counts = removed_by_stage(px, 1000)
    assert sum(counts.values()) + px["valid"] == 1000
    assert counts == {"geometry": 100, "display": 200, "lobe off the monitor": 430,
                      "scattering": 50, "sensor": 20, "decoding": 100}
    assert check_valid({"directions": {"x": {"pixels": px}}}, 1000, False) == []


def test_a_lobe_off_the_monitor_is_refused_naming_that_stage(tmp_path):
    """Ward alphas of 1 with the radiometric estimator: every bundle hangs off the
    monitor. The run is refused (nothing written) and the message names the lobe and its
    share, which matches the dataset the allowed run keeps."""
    from pmdsim import load_run
    from pmdsim.run import run_simulation

    from typer.testing import CliRunner

    from conftest import base_dict, merge
    from pmdsim.cli import app

    toml = tmp_path / "wide.toml"
    toml.write_text(_toml_of(merge(base_dict(), WIDE)))
    result = CliRunner().invoke(app, ["simulate", str(toml), "-o", str(tmp_path / "refused"),
                                      "--no-figures", "--no-diagnostics"])
    assert result.exit_code == 2, result.output
    msg = " ".join(result.output.split())
    assert "error: invalid set-up: brdf:" in msg, msg
    assert "lobe off the monitor" in msg and "0 of 1,280 camera pixels valid" in msg
    assert not (tmp_path / "refused").exists()
    allowed = make_config(**WIDE, diagnostics={"allow_no_valid_pixels": True})
    res = run_simulation(allowed, tmp_path / "kept", figures=False, diagnostics=False)
    note = next(n for n in res.notes if "allow_no_valid_pixels = true" in n)
    ds = load_run(tmp_path / "kept")
    off = np.asarray(ds["lobe_off_monitor"].values, bool)
    share = float(note.split("% have their lobe")[0].split("; ")[-1])
    considered = res.statistics["directions"]["x"]["pixels"]["lobe_off_monitor"]
    assert share == pytest.approx(100 * considered / off.size, abs=0.05)
    assert off.sum() >= considered > 0


def test_a_sweep_point_without_valid_pixels_is_not_a_result(tmp_path):
    """The sweep computes and stores the point (NaN statistics) but exits 1 naming it and
    the directions; with diagnostics.allow_no_valid_pixels the same store is complete."""

    from typer.testing import CliRunner

    from conftest import base_dict, merge
    from pmdsim.cli import app
    from pmdsim.config import parse_config
    from pmdsim.run.sweep import empty_points, load_sweep
    from pmdsim.studies.sweep import plan_sweep

    # washed out: the scattering keeps at most ~45 % of the mirror's modulation at the
    # finer widths, below the asked-for 99 % (the sweep's points mask by modulation)
    data = merge(base_dict(), {"camera": {"resolution": [16, 12], "focal_length_px": 32.0},
                               "brdf": {"alpha_x": 1.0, "alpha_y": 1.0},
                               "sampling": {"n_rays": 8, "theta_max_deg": 4.0},
                               "patterns": {"fringes": {"widths_px": [3.0, 24.0, 200.0]}},
                               "decode": {"min_modulation_ratio": 0.99}})
    lines = [_toml_of(data)]
    lines += ["[sweep]", "decimation = 0", "[sweep.parameters]", '"brdf.alpha_y" = [1.0]']
    cfg = tmp_path / "sweep.toml"
    cfg.write_text("\n".join(lines) + "\n")
    out = tmp_path / "sweep"
    result = CliRunner().invoke(app, ["sweep", str(cfg), "-o", str(out), "--no-figures"])
    assert result.exit_code == 1, result.output
    text = " ".join(result.output.split())
    assert "sweep point 0 (brdf.alpha_y = 1.0): no valid pixel in the x and y fringes" in text
    assert "allow_no_valid_pixels" in text
    ds = load_sweep(out)
    assert bool(ds["done"].values.all())  # stored, and visibly empty
    n_valid = ds["deviation_stats"].sel(quantity="phase_mrad", statistic="n_valid").values
    assert (n_valid == 0).all()
    allowed = parse_config(merge(data, {"diagnostics": {"allow_no_valid_pixels": True},
                                        "sweep": {"decimation": 0,
                                                  "parameters": {"brdf.alpha_y": [1.0]}}}))
    assert empty_points(plan_sweep(allowed), ds) == ()


def _toml_of(data: dict) -> str:
    import json

    out = [f"{k} = {json.dumps(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for section, body in data.items():
        if not isinstance(body, dict):
            continue
        flat = {k: v for k, v in body.items() if not isinstance(v, dict)}
        out += [f"[{section}]"] + [f"{k} = {json.dumps(v)}" for k, v in flat.items()]
        for sub, inner in body.items():
            if isinstance(inner, dict):
                out += [f"[{section}.{sub}]"] + [f"{k} = {json.dumps(v)}" for k, v in inner.items()]
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("command", ["budget", "converge"])
def test_budget_and_converge_rows_without_valid_pixels_are_refused(tmp_path, monkeypatch,
                                                                   command):
    """A row with n_valid = 0 (here: the study's result replaced, budget's wholly, so that
    the wiring is tested without a long run) makes the command exit 2 naming the row, nothing written;
    with diagnostics.allow_no_valid_pixels it is kept with a note."""
    from dataclasses import replace as dc_replace

    from typer.testing import CliRunner

    from conftest import base_dict, merge
    from pmdsim.cli import app
    import pmdsim.run.budget as rb
    import pmdsim.run.convergence as rc

    if command == "budget":
        from pmdsim.studies.budget_error import TABLE_COLUMNS
        from pmdsim.studies.budget import Budget

        def fake(cfg, progress=None, truth="centre"):
            row = dict.fromkeys(TABLE_COLUMNS, 1.0) | {"part": "system", "label": "ideal"}
            return Budget([row | {"effect": "ideal", "direction": d, "n_valid": 0}
                           for d in "xy"] + [row | {"effect": "sensor", "direction": "x",
                                                    "n_valid": 9}])

        monkeypatch.setattr(rb, "budget", fake)
        args = ["--no-figure"]
        says = "budget: no valid pixel in 2 of 3 rows: ideal x; ideal y"
    else:
        real = rc.convergence_study

        def fake(*a, **k):
            res = real(*a, **k)
            return dc_replace(res, rows=[dict(r, n_valid=0) if r["estimator"] == "radiometric"
                                         else r for r in res.rows])

        monkeypatch.setattr(rc, "convergence_study", fake)
        args = ["--camera", "10x8", "--n-values", "8", "--theta", "2", "--no-figure",
                "--no-diagnostics", "--estimators", "paper,radiometric"]
        says = "converge: no valid pixel in 4 of 8 rows: radiometric N = 8 x 10 px"
    small = {"camera": {"resolution": [10, 8], "focal_length_px": 20.0},
             "sampling": {"n_rays": 8},
             "patterns": {"fringes": {"widths_px": [10.0, 200.0]}}}
    for allow in (False, True):
        cfg = tmp_path / f"{allow}.toml"
        cfg.write_text(_toml_of(merge(base_dict(), merge(small, {"diagnostics": {
            "allow_no_valid_pixels": allow}}) if allow else small)))
        out = tmp_path / f"out-{allow}"
        result = CliRunner().invoke(app, [command, str(cfg), "-o", str(out), *args])
        text = " ".join(result.output.split())
        if not allow:
            assert result.exit_code == 2, result.output
            assert "diagnostics.allow_no_valid_pixels: " + says in text, text
            assert not out.exists()
        else:
            assert result.exit_code == 0, result.output
            assert "note: " + says in text and out.is_dir()


def test_a_sweep_point_masks_lobes_off_the_monitor_as_simulate_does():
    """Ward alphas of 1 (radiometric): simulate finds no valid pixel (above); a sweep point
    of the same set-up must not count those pixels as valid either."""
    from pmdsim.measure.chain import QUANTITIES, STATISTICS
    from pmdsim.studies.sweep import measure_point

    cfg = make_config(**merge_small(WIDE))
    stats = measure_point(cfg, 0)["deviation_stats"]
    n_valid = stats[:, list(QUANTITIES).index("phase_mrad"), STATISTICS.index("n_valid")]
    assert (n_valid == 0).all(), n_valid
    narrow = make_config(**merge_small({"sampling": WIDE["sampling"],
                                        "patterns": WIDE["patterns"]}))
    stats = measure_point(narrow, 0)["deviation_stats"]
    assert (stats[:, list(QUANTITIES).index("phase_mrad"), STATISTICS.index("n_valid")] > 0).all()


def merge_small(changes: dict) -> dict:
    from conftest import merge

    return merge({"camera": {"resolution": [16, 12], "focal_length_px": 32.0}}, changes)
