"""The lane-free law's patience with the vehicles it yields to (``_patience``): its memory
is scanned only where it can change, and it answers as the scan of the whole memory did.

Before, every step walked all pairs ever remembered; pairs kept past their timeout are
never forgotten, so on a long run with many yields that walk grew with the run's length
(about 570 pairs after 1 150 s of the width-drop case). ``old_patience`` is that code,
verbatim; random yield requests from a small pool of pairs (so that pairs end, come back,
time out and cool down) must get the same answers and leave the same memory."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from controllers.registry import RoadContext
from controllers.road.lanefree import LaneFreeFlocking, LaneFreeParams

DT = 0.1


def old_patience(law, obs, sc, j, ask) -> np.ndarray:
    """``ask`` (N, K) without the pairs a CAV has yielded to too long (memory by ids)."""
    p = law.params
    t = float(obs.t)
    ids_all = obs.ids.tolist() + (obs.others_ids.tolist() if obs.others_ids is not None
                                  else [None] * (len(sc.s) - sc.n))
    keep = ask.copy()
    rows, cols = np.nonzero(ask)
    keys = list(zip(map(ids_all.__getitem__, rows.tolist()),
                    map(ids_all.__getitem__, j[rows, cols].tolist()), strict=True))
    seen = set(keys)
    since = law._yield_since
    timeout, renew = p.yield_timeout_s, p.yield_timeout_s + p.yield_cooldown_s
    for k, key in enumerate(keys):
        waited = t - since.setdefault(key, t)
        if waited > timeout:
            keep[rows[k], cols[k]] = False
            if waited > renew:
                since[key] = t  # patience again
    for key in [k for k, t0 in law._yield_since.items()
                if k not in seen and t - t0 <= p.yield_timeout_s]:
        del law._yield_since[key]  # the pair ended before the timeout
    return keep


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_patience_answers_and_remembers_as_the_full_scan_did(seed):
    rng = np.random.default_rng(seed)
    n, m, k_side = 6, 10, 4  # CAVs, vehicles, neighbours per CAV
    params = LaneFreeParams()
    new, old = (LaneFreeFlocking(params, RoadContext(dt=DT)) for _ in range(2))
    ids = np.array([f"cav{i}" for i in range(n)], dtype=object)
    others = np.array([f"hdv{i}" for i in range(m - n)], dtype=object)
    sc = SimpleNamespace(s=np.zeros(m), n=n)
    changed = timed_out = stale_max = 0
    ask = np.zeros((n, k_side), bool)
    for step in range(6000):
        if step % 500 == 0:  # new neighbours; requests that switch rarely or often
            j = np.stack([rng.permutation(m)[:k_side] for _ in range(n)])
            flip = float(rng.choice([0.002, 0.01, 0.1]))
        t = round(step * DT, 10)
        obs = SimpleNamespace(t=t, ids=ids, others_ids=others)
        ask = ask ^ (rng.random((n, k_side)) < flip)
        want = old_patience(old, obs, sc, j, ask)
        got = new._patience(obs, sc, j, ask)
        np.testing.assert_array_equal(got, want)
        assert new._yield_since == old._yield_since, step
        changed += int(np.count_nonzero(want != ask))
        stale_max = max(stale_max, len(set(new._yield_since) - new._yield_asked))
        timed_out += int(np.count_nonzero(ask & ~want))
    assert timed_out > 100 and changed == timed_out  # timeouts happened and only they
    # the memory holds pairs kept past their timeout that no longer ask: the old scan
    # walked them every step, the new one never does
    assert stale_max >= 5
