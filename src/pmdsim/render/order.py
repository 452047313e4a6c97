"""The order from a target (issue 36): the cheapest Gauss rule whose stated phase error meets
``sampling.target_error_mrad``, chosen by a :class:`~pmdsim.render.pilot.Pilot` on its
sparse grid of pixels before the camera is rendered once with it.

:func:`choose_order`: the pilot renders the grid at ``n0, 2 n0, 4 n0, ...`` nodes
(``n0 = sampling.n_rays``), each rule's error against the rule four times finer, until the
statement's P95 over the grid (worst fringe, pixels whose fringe keeps a modulation
>= 0.05) is below the target or the next rule would pass ``max_rays`` (after a rule within
:data:`STEPS_WITHIN` x of the target, the rules of :data:`STEPS` times its nodes first, the
cheapest that meets the target taken).
"""

from __future__ import annotations

import numpy as np

from .pilot import FINE_FACTOR, Pilot
from .results import MAX_OFF


def worst_p95(stated: np.ndarray, mod: np.ndarray, min_modulation: float = 0.05) -> float | None:
    """The largest over fringes (leading axes) of the P95 over pixels (last axes) of
    ``stated``, over pixels whose modulation ``mod`` is at least ``min_modulation``."""
    from ..quantiles import percentile

    worst = None
    for idx in np.ndindex(*stated.shape[:2]):
        a = stated[idx][np.isfinite(stated[idx]) & (mod[idx] >= min_modulation)]
        if a.size:
            p = percentile(a, 95)
            worst = p if worst is None else max(worst, p)
    return worst


#: A rule whose grid P95 is within this factor of the target is followed by the rules of
#: :data:`STEPS` times its nodes before the one of twice them (the rules' error falls
#: steeply with the order, and not monotonically between two orders: on Fig. 3 the
#: statement's grid P95 is 0.196 mrad at 64 nodes (4 x 16), 0.060 at 72 (4 x 18), 0.103 at
#: 80 (4 x 20), 0.030 at 88, 0.059 at 96; the 3/2 step alone took 96).
STEPS_WITHIN = 4.0
#: The steps between a rule ``n`` and ``2 n`` (nodes ``n + k n / 8``), tried in turn.
STEPS = (9 / 8, 5 / 4, 11 / 8, 3 / 2)


def choose_order(pilot: Pilot, n0: int, target: float,
                 max_rays: int) -> tuple[int, float | None, list]:
    """``(n_rays, p95, tried)``: the cheapest rule of the ladder ``n0 2^k`` (at most
    ``max_rays``) whose statement's P95 over the grid (per fringe over every grid pixel,
    the worst fringe, modulation >= 0.05) is at most ``target`` (rad), else the largest
    tried; after a rule ``n`` that misses the target by at most :data:`STEPS_WITHIN` x,
    the rules of :data:`STEPS` times ``n`` nodes (9/8 ... 3/2) are tried in turn and the
    first that meets the target is taken (half the order can miss the target by several
    times while a step between it and the next meets it; the error need not fall
    monotonically between two orders: each step's own statement decides). Steps whose rule
    has the node count of one tried before are skipped. ``tried``: [(n_rays, p95 or None)]
    in order."""
    def p95_of(n):
        st = pilot.grid_statement(n)
        fine = pilot.probe(FINE_FACTOR * n)
        mod = np.where(np.nan_to_num(fine.off, nan=1.0) > MAX_OFF, 0.0, fine.mod)
        # per fringe over all grid pixels: (B, gh, gw) -> (B, 1, gh gw)
        return worst_p95(st.reshape(st.shape[0], 1, -1), mod.reshape(st.shape[0], 1, -1))

    def met(p95):
        return p95 is not None and p95 <= target

    tried, seen = [], set()  # the rules tried, and their node counts

    def trial(m, nodes):
        seen.add(nodes)
        p = p95_of(m)
        tried.append((m, p))
        return p

    n = int(n0)
    while True:
        p95 = trial(n, pilot.nodes(n))
        if met(p95):
            return n, p95, tried
        if p95 is not None and p95 <= STEPS_WITHIN * target:
            for m in (int(n * f) for f in STEPS):
                nodes = pilot.nodes(m)
                if not n < m < 2 * n or m > max_rays or nodes in seen:
                    continue
                pm = trial(m, nodes)
                if met(pm):
                    return m, pm, tried
        if 2 * n > max_rays:
            return (*tried[-1], tried)
        n *= 2
