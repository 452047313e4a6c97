"""Every shipped example renders with a mode that states its numerical error (issue 37):
the deterministic Gauss rule (``rule``; its rqmc fallback where the lobe is not smooth) or
``rqmc`` with the reason in the configuration, never the unstated ``stratified`` or
``random`` sample sets. Each example (each variant) is rendered on a reduced camera with
its own sampling settings and its fringes' phase error (or its dot images' error) must be
stated and finite."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pmdsim.config import load_config
from pmdsim.render import Simulation
from pmdsim.studies.convergence import reduced_config

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.toml"))
STATED = ("rule", "rqmc")


def test_there_are_examples():
    assert len(EXAMPLES) >= 10


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_states_its_numerical_error(path):
    cfg = load_config(path)
    text = path.read_text()
    members = cfg.expand() if cfg.variants else [(cfg.name, cfg)]
    for name, member in members:
        assert member.sampling.mode in STATED, (path.name, name, member.sampling.mode)
        assert member.sampling.error_estimate, (path.name, name)
        if member.sampling.mode == "rqmc":  # chosen, not the rule: the config says why
            assert "step function" in text or "not smooth" in text, path.name
        if member.brdf.model == "mirror":
            continue
        small = reduced_config(member, (24, 20))
        sim = Simulation.from_config(small)
        fr_cfg = small.patterns.fringes
        if fr_cfg is not None:
            fr = sim.render_fringes(fr_cfg.widths_px[:1], fr_cfg.directions, fr_cfg.shifts)
            # "rule+rqmc", "rule+box": a display's staircase on the rule, its error by
            # replicates or by a bound (pmdsim.render.control)
            mode = fr.sampling["mode"]
            assert set(mode.split("+")) <= {*STATED, "box"} and fr.sampling["error"], (path.name, mode)
            pe = fr.phase_error()
            assert pe is not None, (path.name, name)
            seen = np.isfinite(fr.images[:, :, 0])
            assert seen.any() and np.all(np.isfinite(pe[seen])), (path.name, name)
        dots = small.patterns.dots
        if dots is not None and fr_cfg is None:
            from pmdsim.patterns import resolve_dots

            images, err = sim.render_dots(resolve_dots(small)[:2], with_error=True)
            assert err is not None and np.all(np.isfinite(err[np.isfinite(images)]))
