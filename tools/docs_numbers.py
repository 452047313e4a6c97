"""Numbers the docs state about the examples, re-computed and compared.

Every entry of :data:`CHECKS` names a document, a regular expression whose groups are the
numbers as written there (with enough of the sentence around them to be unique), the
function that re-computes them from the example (the same code path, on a reduced
configuration where the full run is too slow for CI, and then with a tolerance that covers
the reduction) and the tolerance. A number agrees when ``|doc - computed|`` is at most the
tolerance plus half a unit of the last digit the doc shows (so "0.34" agrees with 0.3412).

    python tools/docs_numbers.py            # check the fast entries (what CI runs)
    python tools/docs_numbers.py --all      # also the slow ones (full-size runs, minutes)
    python tools/docs_numbers.py --update   # write the computed values into the docs
                                            #   (same number of significant digits)
    python tools/docs_numbers.py --list     # the table of checked numbers

Exit code 1 when a number disagrees (each one printed with the document, the line, the
value written and the value computed), 0 otherwise. After a change that moves documented
numbers (a kernel, an example's parameters), ``--update`` (with ``--all``) rewrites them;
review the diff: the prose around a number may need to change too.
"""

from __future__ import annotations

import argparse
import functools
import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

NUMBER = r"(-?\d+(?:\.\d+)?(?:e[-+]?\d+)?)"


@dataclass(frozen=True)
class Check:
    """Numbers of one sentence: ``pattern``'s groups (each :data:`NUMBER`) in ``doc``,
    re-computed by ``compute`` (one value per group), agreeing within ``abs_tol`` or
    ``rel_tol`` (and the digits shown). ``fast``: run by default (CI)."""

    name: str
    doc: str
    pattern: str
    compute: Callable[[], tuple]
    abs_tol: float = 0.0
    rel_tol: float = 0.0
    fast: bool = True
    why: str = ""


def _half_ulp(text: str) -> float:
    """Half a unit of the last digit shown: "0.34" -> 0.005, "142" -> 0.5, "1.2e3" -> 50."""
    mant, _, exp = text.lower().partition("e")
    decimals = len(mant.partition(".")[2])
    return 0.5 * 10.0 ** (-decimals + (int(exp) if exp else 0))


def _format_like(value: float, text: str) -> str:
    """``value`` with as many significant digits as ``text`` shows."""
    mant = text.lower().partition("e")[0].lstrip("-")
    digits = len(mant.replace(".", "").lstrip("0")) or 1
    if "e" in text.lower():
        return f"{value:.{digits - 1}e}"
    if value == 0:
        return text
    decimals = max(0, digits - 1 - math.floor(math.log10(abs(value))))
    return f"{value:.{decimals}f}"


# ----------------------------------------------------------------------------- computations
def _texture(**kw):
    from pmdsim.brdf.turning import texture_parameters

    return texture_parameters(**kw)


def texture_kinematic() -> tuple:
    """README: ``pmdsim texture --feed-um 30 --nose-radius-mm 0.5``."""
    p = _texture(feed_um=30, nose_radius_mm=0.5)
    return (p.kinematic_alpha_radial, p.orders_in_lobe, p.order_spacing_monitor_px)


def texture_rayleigh() -> tuple:
    """docs/texture.md: Rq = 5 nm at 545 nm."""
    p = _texture(feed_um=30, nose_radius_mm=0.5, rq_um=0.005, correlation_length_um=5.0,
                 wavelength_nm=545.0)
    return (p.rayleigh_random, p.specular_share_random)


@functools.cache
def _fig3_config():
    from pmdsim.config import load_config

    return load_config(ROOT / "examples" / "paper_fig3.toml")


def fig3_energy_fraction() -> tuple:
    """README: the share of the Fig. 3 lobe's energy inside its 1 deg cone (diagnostics on
    their coarse pixel grid, the full-size camera)."""
    from pmdsim import Simulation
    from pmdsim.studies.diagnostics import diagnose

    diag = diagnose(Simulation.from_config(_fig3_config()), widths=[400], phase_method="delta")
    return (diag.summary["energy"]["fraction_median"],)


def fig3_modulation() -> tuple:
    """docs/examples.md: median modulation of the X and Y fringes of width 50 of Fig. 3, on
    a 320 x 256 camera with the same field of view (the median over the plate moves by
    < 0.01 with the reduction)."""
    import numpy as np

    from pmdsim import Simulation
    from pmdsim.studies.convergence import reduced_config

    sim = Simulation.from_config(reduced_config(_fig3_config(), (320, 256)))
    fr = sim.render_fringes(widths=[50], directions=["x", "y"], shifts=4)
    with np.errstate(divide="ignore", invalid="ignore"):
        mod = np.abs(fr.sums[:, 0]) / fr.f_hit
    return tuple(float(np.nanmedian(m)) for m in mod)


@functools.cache
def _fig3_simulation():
    from pmdsim import Simulation

    return Simulation.from_config(_fig3_config())


def fig3_rays() -> tuple:
    """docs/performance.md: the rays a Fig. 3 run traces per surface pixel (the rule its
    target's pilot picks) and in all, pilot included, in millions, as the kernels count
    them (``Simulation.rays_traced``, the run's ``rays_traced``)."""
    from pmdsim import Simulation

    sim = Simulation.from_config(_fig3_config())
    fr = sim.render_fringes(widths=[50.0, 400.0, 3200.0], directions=["x", "y"], shifts=4)
    return (float(fr.sampling["nodes"]), sim.rays_traced / 1e6)


def fig3_specular_span() -> tuple:
    """docs/fig3-geometry.md: the monitor range (u, v) the principal rays of Fig. 3 reach."""
    import numpy as np

    geo = _fig3_simulation().geometry()
    return (float(np.nanmin(geo.specular_u)), float(np.nanmax(geo.specular_u)),
            float(np.nanmin(geo.specular_v)), float(np.nanmax(geo.specular_v)))


def fig3_pixel_bundle() -> tuple:
    """docs/fig3-geometry.md: the paper's pixel (1, 1) (row 0, column 0): where P lands,
    how many of its rays hit the monitor (of how many; how many miss) and the range they
    span."""
    import numpy as np

    from dataclasses import replace

    sim = _fig3_simulation()
    geo = sim.geometry()
    # the 8 x 32 rule of 256 nodes the sentence names (the example states a target since
    # issue 36, whose pilot picks the order)
    sim = sim.with_sampling(replace(sim.scene.sampling, n_rays=256, target_error=None))
    u, v, _, _, _ = sim.transport([0], [0])
    u, v = np.asarray(u, float).ravel(), np.asarray(v, float).ravel()
    hit = np.isfinite(u) & np.isfinite(v)
    return (float(geo.specular_u[0, 0]), float(geo.specular_v[0, 0]), int(hit.sum()),
            u.size, int(u.size - hit.sum()), float(u[hit].min()), float(u[hit].max()), float(v[hit].min()), float(v[hit].max()))


@functools.cache
def _turning_statistics() -> dict:
    """The full ``examples/turning_parameters.toml`` run (minutes): statistics per variant."""
    import tempfile

    from pmdsim.config import load_config
    from pmdsim.run import run_simulation

    cfg = load_config(ROOT / "examples" / "turning_parameters.toml")
    cfg = cfg.model_copy(update={"output": cfg.output.model_copy(
        update={"figures": False, "write_images": False})})
    with tempfile.TemporaryDirectory() as tmp:
        res = run_simulation(cfg, Path(tmp) / "run", diagnostics=False)
    return {sub.config.name: sub.statistics for sub in res.variants}


def _turning_row(variant: str) -> Callable[[], tuple]:
    def compute() -> tuple:
        st = _turning_statistics()[variant]["directions"]
        return tuple(st[d][q][s] for q in ("phase_mrad", "coord_px") for d in ("x", "y")
                     for s in ("rms", "p95"))
    compute.__doc__ = f"docs/texture.md: the turning example's {variant} row"
    return compute


def _turning_readme() -> tuple:
    st = _turning_statistics()
    return tuple(st[v]["directions"][d]["phase_mrad"]["rms"]
                 for v in ("ward_equivalent", "kinematic", "diffractive") for d in ("x", "y"))


@functools.cache
def _realistic_budget() -> dict:
    """``pmdsim budget examples/realistic_system.toml`` (tens of minutes on two cores): its
    rows by (effect, direction) and height rows by effect. ``PMDSIM_BUDGET_JSON`` may name
    the ``budget.json`` of that command's run to check (or ``--update``) from instead; it
    must hold the example's configuration as it is now."""
    import json
    import os

    from pmdsim.config import load_config
    from pmdsim.run.budget import run_budget

    cfg = load_config(ROOT / "examples" / "realistic_system.toml")
    path = os.environ.get("PMDSIM_BUDGET_JSON")
    if path:
        data = json.loads(Path(path).read_text())
        from pmdsim.config import physical_estimator
        from pmdsim.scene import resolve_roi

        now = resolve_roi(physical_estimator(cfg)).model_dump(mode="json")
        if data["config"] != json.loads(json.dumps(now)):
            raise SystemExit(f"PMDSIM_BUDGET_JSON={path}: not a budget of the example as it is now")
    else:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            res = run_budget(cfg, Path(tmp) / "budget", figure=False)
            data = {"rows": res.rows, "height_rows": list(res.height_rows)}
    rows = {(r["effect"], r.get("direction")): r for r in data["rows"]}
    rows.update({(r["effect"], "height"): r for r in data["height_rows"]})
    return rows


def budget_scattering() -> tuple:
    """README.md: the realistic example's scattering row through the ideal system."""
    b = _realistic_budget()
    x, y, h = b[("surface_ideal", "x")], b[("surface_ideal", "y")], b[("surface_ideal", "height")]
    return (x["rms_px"], x["rms_px_err"], y["rms_px"], x["rms_urad"], x["rms_urad_err"],
            y["rms_urad"], h["height_rms_nm"], h["height_rms_nm_err"], h["height_pv_nm"],
            h["height_pv_nm_err"])


def budget_numerical() -> tuple:
    """README.md: the numerical error rows of the realistic example's budget."""
    b = _realistic_budget()
    ix, fx, fy = b[("numerical_surface_ideal", "x")], b[("numerical_surface", "x")], b[("numerical_surface", "y")]
    ih = b[("numerical_surface_ideal", "height")]
    return (ix["rms_px"], ix["rms_urad"], ih["height_rms_nm"], ih["height_pv_nm"],
            fx["rms_px"], fy["rms_px"], fx["rms_urad"], fy["rms_urad"])


def budget_full_system() -> tuple:
    """README.md: the realistic example's scattering rows through the full system, with and
    without the sensor, and the no-sensor row's numerical error."""
    b = _realistic_budget()
    out = []
    for eff in ("surface", "surface_noise_free"):
        x, y, h = b[(eff, "x")], b[(eff, "y")], b[(eff, "height")]
        out += [x["rms_px"], x["rms_px_err"], y["rms_px"], y["rms_px_err"], x["rms_urad"],
                x["rms_urad_err"], y["rms_urad"], y["rms_urad_err"], h["height_rms_nm"],
                h["height_rms_nm_err"], h["height_pv_nm"], h["height_pv_nm_err"]]
    nx, ny, nh = (b[("numerical_surface_noise_free", d)] for d in ("x", "y", "height"))
    return tuple(out) + (nx["rms_px"], ny["rms_px"], nx["rms_urad"], ny["rms_urad"],
                         nh["height_rms_nm"], nh["height_pv_nm"])


# ----------------------------------------------------------------------------- the table
_ROW = r" \| " + NUMBER + r" / " + NUMBER
_PM2 = NUMBER + r" ± " + NUMBER + r" / " + NUMBER + r" ± " + NUMBER
CHECKS = [
    Check("texture-kinematic", "README.md",
          r"equivalent Ward alphas \(" + NUMBER + r" radial[\s\S]*?diffractive: " + NUMBER
          + r" orders inside the lobe, " + NUMBER + r" monitor px apart",
          texture_kinematic, why="closed form"),
    Check("texture-rayleigh", "docs/texture.md",
          r"Rq = 5 nm at 545 nm it is " + NUMBER + r", share " + NUMBER,
          texture_rayleigh, why="closed form"),
    Check("fig3-energy", "README.md",
          r"fraction_median\"\]\)\s+# " + NUMBER + r": lobe energy inside 1 deg",
          fig3_energy_fraction, why="quadrature on the diagnostics' grid, full camera"),
    Check("fig3-modulation", "docs/examples.md",
          r"keep a median modulation\s+of " + NUMBER + r" and the Y fringes " + NUMBER,
          fig3_modulation, abs_tol=0.01, why="320 x 256 camera, same field of view"),
    Check("fig3-specular-span", "docs/fig3-geometry.md",
          r"The specular points span u = " + NUMBER + r" \.\.\. " + NUMBER + r" and v = "
          + NUMBER + r" \.\.\. " + NUMBER, fig3_specular_span, why="geometry, full camera"),
    Check("fig3-rays", "docs/performance.md",
          r"the rays a Fig\. 3 run traces \(" + NUMBER + r" per surface pixel, " + NUMBER
          + r" M\s+in all", fig3_rays, why="the pilot's pick and the render, full camera"),
    Check("fig3-pixel-bundle", "docs/fig3-geometry.md",
          r"P lands at \(u, v\) = \(" + NUMBER + r", " + NUMBER + r"\); " + NUMBER
          + r" of its " + NUMBER + r" rays hit the\s+monitor, " + NUMBER
          + r" leave it[\s\S]*?The bundle spans u = " + NUMBER + r" \.\.\. "
          + NUMBER + r", v = " + NUMBER + r" \.\.\. " + NUMBER, fig3_pixel_bundle,
          why="the paper's pixel (1, 1), its 100 rays"),
    Check("turning-ward", "docs/texture.md",
          r"\| Ward, equivalent alphas \(0\.0020 / 0\.0246\)" + _ROW * 4,
          _turning_row("ward_equivalent"), fast=False, why="the full example run"),
    Check("turning-kinematic", "docs/texture.md",
          r"\| turned, geometric \(kinematic\)" + _ROW * 4,
          _turning_row("kinematic"), fast=False, why="the full example run"),
    Check("turning-diffractive", "docs/texture.md",
          r"\| turned, diffractive \(R, G, B\)" + _ROW * 4,
          _turning_row("diffractive"), fast=False, why="the full example run"),
    Check("turning-readme", "README.md",
          r"phase-deviation RMS \(X / Y\) is\s+" + NUMBER + r" / " + NUMBER
          + r" mrad with the equivalent Ward lobe, " + NUMBER + r" / " + NUMBER
          + r" mrad with the kinematic density[\s\S]*?and\s+" + NUMBER + r" / " + NUMBER
          + r" mrad with the diffractive orders", _turning_readme, fast=False,
          why="the full example run"),
    Check("budget-scattering", "README.md",
          r"\| \*\*surface scattering \(ideal system\)\*\* \| " + NUMBER + r" ± " + NUMBER + r" / "
          + NUMBER + r" \| " + NUMBER + r" ± " + NUMBER + r" / " + NUMBER + r" \| " + NUMBER
          + r" ± " + NUMBER + r" / " + NUMBER + r" ± " + NUMBER + r" \|", budget_scattering,
          fast=False, why="the full example's budget (deterministic rule, no sensor)"),
    Check("budget-numerical", "README.md",
          r"\| numerical error of that row \| " + NUMBER + r" / < 1e-8 \| " + NUMBER
          + r" / < 1e-5 \| " + NUMBER + r" / " + NUMBER + r" \|[\s\S]*?\| numerical error of "
          r"the full system's row \| " + NUMBER + r" / " + NUMBER + r" \| "
          + NUMBER + r" / " + NUMBER + r" \|", budget_numerical, rel_tol=0.05, fast=False,
          why="the full example's budget (box rule, seeded sensor)"),
    Check("budget-full-system", "README.md",
          r"\| surface scattering \(full system, incl\. the noise of both captures\) \| "
          + r" \| ".join([_PM2] * 3) + r" \|\n\| the same renders without the sensor \(the "
          r"scattering's own part\) \| " + r" \| ".join([_PM2] * 3)
          + r" \|[\s\S]*?\| numerical error of the no-sensor row \| "
          + r" \| ".join([NUMBER + r" / " + NUMBER] * 3) + r" \|",
          budget_full_system, rel_tol=0.05, fast=False,
          why="the full example's budget (box rule, seeded sensor)"),
]


# ----------------------------------------------------------------------------- checking
@dataclass
class Result:
    check: Check
    line: int
    written: list[str]
    computed: tuple
    bad: list[int]


def find(check: Check, text: str) -> re.Match:
    matches = list(re.finditer(check.pattern, text))
    if len(matches) != 1:
        raise LookupError(f"{check.name}: the pattern matches {len(matches)} times in "
                          f"{check.doc} (want exactly one; the sentence was reworded?)")
    return matches[0]


def evaluate(check: Check) -> Result:
    text = (ROOT / check.doc).read_text(encoding="utf-8")
    m = find(check, text)
    written = list(m.groups())
    computed = tuple(float(v) for v in check.compute())
    if len(computed) != len(written):
        raise ValueError(f"{check.name}: {len(written)} numbers written, {len(computed)} computed")
    bad = [k for k, (w, c) in enumerate(zip(written, computed))
           if not abs(float(w) - c) <= (check.abs_tol + check.rel_tol * abs(c)
                                        + _half_ulp(w)) * (1 + 1e-9)]
    return Result(check, text.count("\n", 0, m.start()) + 1, written, computed, bad)


def update(result: Result) -> bool:
    """Write the computed values into the document; True when it changed."""
    path = ROOT / result.check.doc
    text = path.read_text(encoding="utf-8")
    m = find(result.check, text)
    out, last = [], 0
    for k, (w, c) in enumerate(zip(result.written, result.computed)):
        out += [text[last:m.start(k + 1)], _format_like(c, w) if k in result.bad else w]
        last = m.end(k + 1)
    new = "".join(out) + text[last:]
    if new != text:
        path.write_text(new, encoding="utf-8")
    return new != text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--all", action="store_true", help="also the slow checks (full runs)")
    ap.add_argument("--update", action="store_true", help="write the computed values")
    ap.add_argument("--list", action="store_true", help="list the checked numbers")
    ap.add_argument("names", nargs="*", help="only these checks")
    args = ap.parse_args(argv)
    checks = [c for c in CHECKS if (not args.names or c.name in args.names)
              and (args.all or c.fast or c.name in args.names)]
    if args.list:
        for c in CHECKS:
            print(f"{c.name:22} {c.doc:24} {'fast' if c.fast else 'slow'}  tol abs {c.abs_tol:g} "
                  f"rel {c.rel_tol:g}  ({c.why})")
        return 0
    failed = 0
    for c in checks:
        r = evaluate(c)
        shown = ", ".join(f"{w} (computed {v:.6g})" for w, v in zip(r.written, r.computed))
        if not r.bad:
            print(f"ok    {c.name}: {shown}")
            continue
        if args.update:
            update(r)
            print(f"wrote {c.doc}:{r.line} {c.name}: {shown}")
            continue
        failed += 1
        print(f"FAIL  {c.doc}:{r.line} {c.name}: "
              + ", ".join(f"written {r.written[k]}, computed {r.computed[k]:.6g}" for k in r.bad)
              + f" (tolerance abs {c.abs_tol:g}, rel {c.rel_tol:g} and the digits shown)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
