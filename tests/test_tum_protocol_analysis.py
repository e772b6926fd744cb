"""TUM LaneFreeDrive's ring protocol (cosim.analysis.tum_protocol): their averaging
reproduced on synthetic runs, the 5 %-HDV loss, and the report it writes."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from cosim.analysis import tum_protocol as tp
from cosim.analysis.report import analyse
from cosim.analysis.tables import load_results

SHARES = (0.95, 1.0)
DENSITIES = (50.0, 100.0, 400.0)


def _flow(share: float, density: float, seed: int) -> float:
    """A made-up fundamental diagram, veh/h: peak at 100 veh/km, seeds apart by 10."""
    peak = 10000.0 if share == 1.0 else 8000.0
    return peak * (density / 100.0 if density <= 100 else 100.0 / density) + 10.0 * seed


@pytest.fixture
def protocol_dir(tmp_path):
    rows = []
    for share in SHARES:
        for dens in DENSITIES:
            for seed in (1, 2, 3):
                q = _flow(share, dens, seed)
                rows.append({
                    "run_id": f"r{share}_{dens:g}_{seed}", "status": "ok", "error": "",
                    "demand.cav_share": share, "demand.ring_density_vpkm": dens, "seed": seed,
                    "network.kind": "ring", tp.DETECTOR_COLUMN: q, "edie_flow_vph": q + 5.0,
                    "edie_density_vpkm": dens, "space_mean_speed_mps": q / dens / 3.6,
                    "flow_drift": -0.01 * seed, "collisions_geometric_cav": 0,
                })
    rows.append({"run_id": "bad", "status": "failed", "error": "boom",
                 "demand.cav_share": 1.0, "demand.ring_density_vpkm": 400.0, "seed": 4})
    pd.DataFrame(rows).to_csv(tmp_path / "results.csv", index=False)
    (tmp_path / "sweep.json").write_text(json.dumps({
        "name": "tum_protocol", "axes": {"demand.cav_share": list(SHARES),
                                         "demand.ring_density_vpkm": list(DENSITIES)},
        "seeds": [1, 2, 3], "variants": []}))
    return tmp_path


def test_the_share_table_is_the_mean_over_densities_and_seeds_as_tum_averaged(protocol_dir):
    res = load_results(protocol_dir)
    assert tp.is_tum_protocol(res)
    shares = tp.share_table(res)
    assert list(shares["cav_share"]) == list(SHARES)
    for share in SHARES:
        r = shares[shares["cav_share"] == share].iloc[0]
        want = np.mean([_flow(share, d, s) for d in DENSITIES for s in (1, 2, 3)])
        assert r["flow_vph"] == pytest.approx(want)
        assert (r["n_runs"], r["densities"], r["seeds"]) == (9, 3, 3)
        assert r["tum_vph"] == tp.TUM_TABLE_VPH[share]
        assert r["ours_over_tum"] == pytest.approx(want / tp.TUM_TABLE_VPH[share])
        # the peak of the seed-mean curve, where it is
        assert r["max_flow_vph"] == pytest.approx(_flow(share, 100.0, 2))
        assert r["max_at_vpkm"] == 100.0
        assert r["ci_low_vph"] < r["flow_vph"] < r["ci_high_vph"]
    assert shares["tum_max_vph"].iloc[-1] == max(tp.TUM_FIGURE_VPH[1.0])


def test_the_density_table_keeps_each_density_and_the_seed_range(protocol_dir):
    dens = tp.density_table(load_results(protocol_dir))
    assert len(dens) == len(SHARES) * len(DENSITIES)
    r = dens[(dens["cav_share"] == 1.0) & (dens["density_vpkm"] == 400.0)].iloc[0]
    assert r["n_runs"] == 3  # the failed run is not counted
    assert r["flow_vph"] == pytest.approx(_flow(1.0, 400.0, 2))
    assert (r["flow_min_vph"], r["flow_max_vph"]) == (_flow(1.0, 400.0, 1), _flow(1.0, 400.0, 3))
    assert r["edie_flow_vph"] == pytest.approx(r["flow_vph"] + 5.0)
    assert r["flow_drift"] == pytest.approx(0.03)
    assert r["tum_vph"] == tp.TUM_FIGURE_VPH[1.0][-1]
    hidden = dens[(dens["cav_share"] == 0.95) & (dens["density_vpkm"] == 50.0)].iloc[0]
    assert math.isnan(hidden["tum_vph"]) and math.isnan(hidden["ours_over_tum"])


def test_the_loss_at_five_percent_humans():
    shares = pd.DataFrame({"cav_share": [0.95, 1.0], "flow_vph": [9000.0, 10000.0]})
    assert tp.hdv_loss(shares) == pytest.approx(0.1)
    assert math.isnan(tp.hdv_loss(shares.iloc[1:]))
    # TUM's own numbers: 1 - 13 337.25 / 15 503.75
    tum = pd.DataFrame({"cav_share": list(tp.TUM_TABLE_VPH),
                        "tum_vph": list(tp.TUM_TABLE_VPH.values())})
    assert tp.hdv_loss(tum, "tum_vph") == pytest.approx(1 - 13337.25 / 15503.75)


def test_analyse_writes_the_protocol_report_and_figure(protocol_dir):
    a = analyse(protocol_dir)
    out = a.out_dir
    md = (out / "tum_protocol.md").read_text()
    assert "x = 339.09 m" in md and "loss at 5 % human drivers" in md
    assert (out / "figures" / "tum_protocol_fd.png").stat().st_size > 10_000
    shares = pd.read_csv(out / "tum_protocol_shares.csv")
    assert list(shares["cav_share"]) == list(SHARES)
    assert "tum_protocol.md" in (out / "report.md").read_text()


def test_other_sweeps_are_not_taken_for_the_protocol(tmp_path):
    pd.DataFrame([{"run_id": "a", "status": "ok", "demand.cav_share": 1.0,
                   "demand.ring_density_vpkm": 100.0, "seed": 1, "edie_flow_vph": 1.0,
                   "flow_x500_vph": 1.0}]).to_csv(tmp_path / "results.csv", index=False)
    assert not tp.is_tum_protocol(load_results(tmp_path))


def test_a_density_with_an_extra_seed_weighs_as_one_density(protocol_dir):
    """TUM's mean is over densities of equal weight: an extra run at one density (an
    interrupted sweep's next seed) changes that density's mean, not the weights."""
    t = pd.read_csv(protocol_dir / "results.csv")
    extra = t[(t["run_id"] == "r1.0_50_1")].assign(run_id="extra", seed=4)
    extra[tp.DETECTOR_COLUMN] = 99999.0
    pd.concat([t, extra]).to_csv(protocol_dir / "results.csv", index=False)
    r = tp.share_table(load_results(protocol_dir)).set_index("cav_share").loc[1.0]
    means = [np.mean([_flow(1.0, d, s) for s in (1, 2, 3)]) for d in DENSITIES]
    means[0] = np.mean([_flow(1.0, 50.0, s) for s in (1, 2, 3)] + [99999.0])
    assert r["flow_vph"] == pytest.approx(np.mean(means))
    # the CI is over the seeds that ran every density (1-3), not seed 4
    full = [np.mean([_flow(1.0, d, s) for d in DENSITIES]) for s in (1, 2, 3)]
    assert r["ci_high_vph"] - r["flow_vph"] == pytest.approx(
        4.302653 * np.std(full, ddof=1) / np.sqrt(3), rel=1e-4)


def test_four_rows_at_tums_margins_give_tums_congested_branch():
    """The independent expectation the docs set beside the runs: 4 rows at TUM's margins
    (T 0.5 s, no standstill gap) land within 4 % of TUM's figure at 250-400 veh/km; at our
    default margins (T 0.6 s, 2.5 m) they give 8 280 veh/h at 400 veh/km, and TUM's
    margins in 3 rows would fall short of TUM at every congested density."""
    for k in (250.0, 300.0, 350.0, 400.0):
        tum = tp._tum_at(1.0, k)
        four = tp.rows_equilibrium_flow_vph(k, 4, 0.5, 0.0)
        assert abs(four / tum - 1) < 0.04
        assert tp.rows_equilibrium_flow_vph(k, 3, 0.5, 0.0) < 0.9 * tum
    assert round(tp.rows_equilibrium_flow_vph(400.0, 4, 0.6, 2.5)) == 8280
    assert tp.rows_equilibrium_flow_vph(50.0, 4, 0.5, 0.0, free_speed_mps=30.0) == 5400.0


def test_mixed_rows_equilibrium_reduces_to_the_rows_and_prices_the_humans():
    for k in (250.0, 400.0):
        assert tp.mixed_rows_equilibrium_flow_vph(k, 4, 1.0, 0.5, 0.9, 0.5, 1.5) == \
            pytest.approx(tp.rows_equilibrium_flow_vph(k, 4, 0.5, 0.5))
    # 5 % humans with a 1.5 s reaction time, CAVs at 0.5 s behind everyone: mean time gap
    # 0.55 s, fixed length 4.05 + 0.95 x 0.5 m; 100 veh/km per row
    q = tp.mixed_rows_equilibrium_flow_vph(400.0, 4, 0.95, 0.5, 0.5, 0.5, 1.5)
    assert q == pytest.approx(400 * (1000 / 100 - 4.05 - 0.475) / 0.55 * 3.6)
    assert 1 - q / tp.rows_equilibrium_flow_vph(400.0, 4, 0.5, 0.5) == pytest.approx(
        0.087, abs=0.002)
    # a longer time gap behind a human costs flow
    assert tp.mixed_rows_equilibrium_flow_vph(400.0, 4, 0.95, 0.5, 0.9, 0.5, 1.5) < q
