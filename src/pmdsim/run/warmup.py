"""Fill the Numba cache: ``pmdsim warmup``.

pmdsim's kernels are compiled by Numba on first use and cached on disk (``cache=True``:
next to the installed modules in ``__pycache__``, or in ``NUMBA_CACHE_DIR``). The first run
after an install would pay for compiling every kernel it calls (about 13 s for the Fig. 3
run on a 2-core machine). :func:`warmup` runs a few tiny simulations that call every kernel
path a run can take (the cone and radiometric estimators, Ward, Beckmann and the mirror,
nearest and continuous monitors, fringes, dots and monitor images, decoding with each
unwrapping method, the run diagnostics, camera optics, curved surfaces, display physics
and the sensor), so that it is paid once, at install time:

    pip install pmdsim && pmdsim warmup

This is a cache warm-up, not ahead-of-time compilation: the cache is specific to the
machine's CPU and the installed Numba version, and Numba recompiles by itself when either
changes.

It also byte-compiles the package's own modules (:mod:`compileall`): ``pip install -e``
leaves an editable checkout without ``.pyc`` files, and where Python does not write them
itself (``PYTHONDONTWRITEBYTECODE``, a read-only checkout for others) every run would
compile its sources again (about 0.15 s of each start).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from ..config import parse_config

#: A 24 x 20 camera on the set-up of the paper's Fig. 3.
_BASE = {
    "camera": {"resolution": [24, 20], "pixel_pitch_mm": 0.256, "focal_length_mm": 50.0,
               "position_mm": [-845.236523481399, 0.0, 1812.6155740733],
               "look_at_mm": [0.0, 0.0, 0.0]},
    "monitor": {"resolution": [1920, 1080], "pixel_pitch_mm": 0.25,
                "centre_mm": [253.57095704442, 0.0, 543.78467222199],
                "look_at_mm": [0.0, 0.0, 0.0]},
    "surface": {"size_mm": [300.0, 200.0]},
    "brdf": {"model": "ward", "alpha_x": 0.025, "alpha_y": 0.002},
    "sampling": {"n_rays": 16},  # the smallest Gauss rule that states its error
    "patterns": {"fringes": {"widths_px": [50.0, 400.0, 3200.0]},
                 "dots": {"positions_px": [[960.0, 540.0]], "size_px": 241}},
    # the runs only compile the kernels: 16 rays on a 24 x 20 camera decode few pixels,
    # which is no result but no error either here
    "diagnostics": {"grid": [3, 2], "allow_no_valid_pixels": True},
    "output": {"write_images": False, "figures": False},
}

#: What each tiny run adds to the base: together they reach every kernel path.
CASES = {
    "ward-nearest-paper": {},
    "ward-continuous-random": {"monitor": dict(_BASE["monitor"], pixel_model="continuous"),
                               "sampling": {"n_rays": 8, "mode": "random"}},
    "ward-radiometric-heterodyne": {"sampling": {"n_rays": 16, "estimator": "radiometric"},
                                    "patterns": {"fringes": {"widths_px": [50.0, 56.0, 64.0]}},
                                    "decode": {"method": "heterodyne", "enabled": "auto"}},
    "beckmann-weighted-gamma": {"brdf": {"model": "beckmann", "alpha_u": 0.02, "alpha_v": 0.004},
                                "sampling": {"n_rays": 16, "estimator": "weighted_mean"},
                                "monitor": dict(_BASE["monitor"], gamma=2.2),
                                "patterns": {"fringes": {"widths_px": [21.0, 25.0, 32.0]}},
                                "decode": {"method": "number_theoretic"}},
    "beckmann-radiometric-continuous-gamma": {
        "brdf": {"model": "beckmann", "alpha_u": 0.02, "alpha_v": 0.004},
        "sampling": {"n_rays": 16, "estimator": "radiometric"},
        "monitor": dict(_BASE["monitor"], pixel_model="continuous", gamma=2.2)},
    # camera optics (sub-pixels, distortion), a curved surface, display physics, the sensor
    "optics-sphere-display-sensor": {
        "camera": dict(_BASE["camera"], subpixels=2, k1=0.01),
        "surface": {"type": "sphere", "radius_mm": 5000.0,
                    "aperture": {"shape": "circular", "radius_mm": 110.0}},
        "monitor": dict(_BASE["monitor"], falloff_exponent=1.0, cover_glass_thickness_mm=1.0,
                        flatness_coefficients_mm=[[0.0, 0.0], [0.0, 1e-6]]),
        "sensor": {"enabled": True}},
}


def warmup_configs(image: str | None = None) -> dict:
    """{case: RunConfig} of the tiny warm-up runs; ``image``: a 1920 x 1080 monitor image
    file shown in the first case (the monitor-image path)."""
    out = {}
    for k, (name, extra) in enumerate(CASES.items()):
        d = dict(_BASE, name=f"warmup-{name}", **extra)
        if k == 0 and image is not None:
            d["patterns"] = dict(d["patterns"], images={"files": [image]})
        out[name] = parse_config(d, f"warmup {name}")
    return out


def byte_compile(package: str | Path | None = None) -> bool:
    """Write the ``.pyc`` files of the package folder ``package`` (default: this installed
    package; nothing where they are current or the folder is read-only); True when every
    module compiled."""
    import compileall

    package = Path(__file__).resolve().parents[1] if package is None else Path(package)
    return bool(compileall.compile_dir(package, quiet=2))


def warmup(progress=None) -> dict:
    """Byte-compile the package and run every warm-up case (in a temporary folder, nothing
    kept); returns {case: s}."""
    from .simulate import run_simulation

    byte_compile()
    out = {}
    import numpy as np
    from PIL import Image

    with tempfile.TemporaryDirectory(prefix="pmdsim-warmup-") as tmp:
        image = Path(tmp) / "grey.png"
        Image.fromarray(np.full((1080, 1920), 128, np.uint8)).save(image)
        for k, (name, cfg) in enumerate(warmup_configs(str(image)).items()):
            t = time.perf_counter()
            run_simulation(cfg, Path(tmp) / name, figures=False)
            out[name] = time.perf_counter() - t
            if progress is not None:
                progress(k + 1, len(CASES))
        # ``pmdsim decode`` of camera images, 8 and 16 bit: its kernels for such frames
        # (the runs above decode float32 images only)
        import tifffile

        from .decode_run import decode_files, make_setup

        setup = make_setup(widths=[50.0, 400.0], shifts=4, extent_px=300.0)
        for dtype in (np.uint8, np.uint16):
            name = np.dtype(dtype).name
            paths = []
            for k in range(8):
                paths.append(Path(tmp) / f"{name}-{k}.tif")
                tifffile.imwrite(paths[-1], (np.random.default_rng(k).random((12, 10)) * 200
                                             ).astype(dtype))
            decode_files(paths, Path(tmp) / f"decode-{name}", setup, figures=False)
    # the percentiles of large samples (a real camera's maps; the tiny runs above take
    # the small samples' path): their window pass, for both float types
    from ..quantiles import WINDOW_MIN, median, percentile

    for dtype in (np.float32, np.float64):
        sample = np.random.default_rng(0).random(WINDOW_MIN).astype(dtype)
        percentile(sample, 95)
        median(sample)
    return out


__all__ = ["warmup", "warmup_configs", "byte_compile", "CASES"]
