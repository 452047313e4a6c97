"""The vector width of the compiled kernels (``pmdsim.kernels._jit.wide_vector_features``):
when pmdsim asks LLVM for 512-bit vectors, who overrides it, and that the rendered and
decoded fringes do not depend on it beyond rounding (fresh interpreters, one per width)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pmdsim.kernels import _jit

SRC = str(Path(__file__).parents[2] / "src")


class _Features(dict):
    def flatten(self):
        return ",".join(("+" if v else "-") + k for k, v in self.items())


@pytest.fixture
def host(monkeypatch):
    """A fake host: CPU name and AVX-512 flag set by the test, no user settings."""
    import llvmlite.binding as ll

    for name in ("NUMBA_CPU_FEATURES", "NUMBA_CPU_NAME", "NUMBA_ENABLE_AVX",
                 "PMDSIM_VECTOR_BITS"):
        monkeypatch.delenv(name, raising=False)
    state = {"name": "sapphirerapids", "avx512f": True}
    monkeypatch.setattr(ll, "get_host_cpu_name", lambda: state["name"])
    monkeypatch.setattr(ll, "get_host_cpu_features",
                        lambda: _Features(avx2=True, avx512f=state["avx512f"], fma=True))
    return state


def test_wide_vectors_on_a_listed_avx512_cpu(host):
    assert _jit.wide_vector_features() == "+avx2,+avx512f,+fma,-prefer-256-bit"


def test_llvms_default_on_other_cpus(host):
    host["name"] = "skylake-avx512"  # AVX-512 with the clock penalty: LLVM's default stays
    assert _jit.wide_vector_features() is None
    host.update(name="znver4", avx512f=False)  # listed, but AVX-512 off (e.g. a VM's mask)
    assert _jit.wide_vector_features() is None


@pytest.mark.parametrize("name, value", [
    ("PMDSIM_VECTOR_BITS", "256"), ("NUMBA_CPU_FEATURES", "+avx2"),
    ("NUMBA_CPU_NAME", "generic"), ("NUMBA_ENABLE_AVX", "0")])
def test_the_users_setting_wins(host, monkeypatch, name, value):
    monkeypatch.setenv(name, value)
    assert _jit.wide_vector_features() is None


def test_the_setting_reaches_numbas_code_generator():
    """This process: what pmdsim chose is what Numba compiles (and caches) for."""
    from numba.core.registry import cpu_target

    tm = cpu_target.target_context.codegen()._tm_features
    if os.environ.get("NUMBA_CPU_FEATURES") is None:
        pytest.skip("no CPU features set (not a listed AVX-512 CPU, or a user's setting)")
    assert tm == os.environ["NUMBA_CPU_FEATURES"]


_RENDER = r"""
import json, sys
import numpy as np
sys.path.insert(0, {tests!r})
from conftest import base_dict, merge
from pmdsim.config import parse_config
from pmdsim.render import Simulation
cfg = parse_config(merge(base_dict(), {{
    "sampling": {{"n_rays": 100, "mode": "rule", "theta_max_deg": 1.0}},
    "monitor": {{"pixel_model": "continuous"}}}}))
sim = Simulation.from_config(cfg)
res = sim.render_fringes((23.0, 184.0), ("x", "y"), 4)
from numba.core.registry import cpu_target
np.savez({out!r}, images=res.images, sums=res.sums, err=res.stated_phase_error)
print(json.dumps(cpu_target.target_context.codegen()._tm_features.endswith("-prefer-256-bit")))
"""


def test_the_render_does_not_depend_on_the_vector_width(tmp_path):
    """The Fig. 3 kernel path (cone rule, Ward, continuous monitor: the harmonic sums) with
    LLVM's 256-bit vectors and with pmdsim's choice: the same complex sums to 1e-12 of the
    largest sum, the float32 images and the stated phase errors to their rounding
    (reassociated sums round differently per vector width)."""
    if _jit.wide_vector_features() is None and "-prefer-256-bit" not in os.environ.get(
            "NUMBA_CPU_FEATURES", ""):
        pytest.skip("this CPU keeps LLVM's default vectors: both widths are the same code")
    runs = {}
    for bits in ("256", "auto"):
        out = tmp_path / f"{bits}.npz"
        env = {k: v for k, v in os.environ.items()
               if k not in ("NUMBA_CPU_FEATURES", "PMDSIM_VECTOR_BITS")}
        env["PYTHONPATH"] = SRC
        if bits == "256":  # its own cache: compiled for 256-bit vectors in the test
            env.update(PMDSIM_VECTOR_BITS="256", NUMBA_CACHE_DIR=str(tmp_path / "cache-256"))
        code = _RENDER.format(tests=str(Path(__file__).parents[1]), out=str(out))
        p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                           text=True, timeout=900)
        assert p.returncode == 0, p.stderr[-3000:]
        wide = json.loads(p.stdout.strip().splitlines()[-1])
        assert wide is (bits != "256")  # each process compiled for the width asked for
        runs[bits] = dict(np.load(out))
    for key in ("images", "sums", "err"):  # images float32: to their rounding
        a, b = runs["256"][key], runs["auto"][key]
        assert np.array_equal(np.isnan(a), np.isnan(b)) and np.isfinite(a).any()
        # the stated phase error (rad) from the pilot: its floors read the float32 images
        tol = (1e-6 if a.dtype == np.float32 or key == "err" else 1e-12) * np.nanmax(
            np.abs(runs["256"][key]))
        assert np.nanmax(np.abs(a - b)) <= tol, key
