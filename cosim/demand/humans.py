"""Which human drivers a run has: SUMO's calibrated SL2015 drivers, or TUM's.

``demand.human_model`` picks the human drivers (HDVs) of every run:

``"sl2015"`` (default)
    SUMO's Krauss car following and SL2015 lateral model with the constants calibrated in
    :mod:`cosim.demand.spec` (``HDV_*``): tau 1.3 s, dawdling 0.5, a 1 m lateral gap,
    pushy and assertive enough not to stand behind a stopped car.
``"tum_trb2024"``, ``"tum_trc2025"``
    TUM LaneFreeDrive's ``StripBasedHuman`` (repository TUM-VT/LaneFreeDrive,
    ``src/StripBasedHuman.cpp``), with the constants of their TRB 2024 runs (tag
    ``Paper-TRB-2024``, ``python_src/trb_const_config.ini``: the runs behind the
    density-averaged table our README quotes) or of their TRC 2025 runs (tag
    ``TRC-2025-HDVs_and_LFT``, ``ring_road_trc_2025/trc_2025_default_settings.ini``).

What of TUM's model is reproduced, and how:

* **Longitudinal, the same law.** Their safe speed is Krauss's,
  ``v_safe = -tau b + sqrt((tau b)^2 + v_l^2 + 2 b (g - g_min))``, the next speed
  ``min(v_safe, v_des, v + a dt)``, braking at most ``b`` (TRC 2025: up to the maximum
  braking when the gap is shorter than the braking distance plus ``g_min``); no dawdling.
  SUMO's Krauss model is that law: ``accel`` = a, ``decel`` = b, ``emergencyDecel`` = the
  maximum braking, ``minGap`` = ``g_min``, ``sigma`` = 0.
* **A reaction time per vehicle**, drawn once from N(1.5, 0.5) s as theirs. They do not
  clip it (0.13 % of draws are negative); here it is clipped below at
  :data:`TAU_MIN_S` and rounded to 0.01 s, and each value is its own vType
  (``hdv_<class>_t<centiseconds>``), so the route file holds the whole draw.
* **Lateral, approximated.** Their human moves one strip (0.1 m, TRC 2025: 0.05 m) per
  step of 0.25 s towards the side whose strips promise the higher safe speed, after a
  benefit summed with memory passes a threshold, if the strip is free one step ahead.
  SUMO's SL2015 also moves for speed gain, not by strips; here it gets their lateral
  speed (one strip per step: 0.4 m/s, TRC 2025 0.2 m/s) and a lateral gap of 0.2 m
  (their free-strip check widens the other car by 20 %), SL2015's defaults otherwise.
* **Not reproduced**: their ballistic position update (our runs use SUMO's Euler update,
  ``--step-method.ballistic false``), and their strips' look-ahead.

A human model is a property of SUMO's drivers: the SUMO-free road world refuses any but
``"sl2015"`` (:func:`cosim.config.checks.check_scenario`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The human models ``demand.human_model`` accepts.
HUMAN_MODELS = ("sl2015", "tum_trb2024", "tum_trc2025")

#: Lower bound of a drawn reaction time, s: TUM's step length (they do not clip).
TAU_MIN_S = 0.25


@dataclass(frozen=True)
class KraussHuman:
    """One of TUM's human-driver parameter sets, as SUMO vType attributes.

    Attributes:
        accel_mps2: maximum acceleration a, m/s^2.
        decel_mps2: comfortable deceleration b of the safe speed, m/s^2.
        emergency_decel_mps2: the hardest braking, m/s^2.
        min_gap_m: standstill gap g_min in the safe speed, m.
        tau_mean_s, tau_sd_s: the normal distribution of the reaction time, s.
        max_speed_lat_mps: lateral speed, m/s (one strip per step of 0.25 s).
        min_gap_lat_m: lateral gap to side neighbours, m.
        source: where the values are from.
    """

    accel_mps2: float
    decel_mps2: float
    emergency_decel_mps2: float
    min_gap_m: float
    tau_mean_s: float
    tau_sd_s: float
    max_speed_lat_mps: float
    min_gap_lat_m: float
    source: str

    def vtype_attributes(self, tau_s: float, lanes: bool) -> dict[str, str]:
        """Car-following and lane-change attributes of a ``<vType>`` with reaction time
        ``tau_s`` (s), in the order they are written (``lanes``: LC2013 on a lane road)."""
        attrs = {"minGap": f"{self.min_gap_m}", "accel": f"{self.accel_mps2}",
                 "decel": f"{self.decel_mps2}",
                 "emergencyDecel": f"{self.emergency_decel_mps2}", "sigma": "0.0",
                 "tau": f"{tau_s:.2f}"}
        if lanes:
            attrs["laneChangeModel"] = "LC2013"
        else:
            attrs.update(laneChangeModel="SL2015", latAlignment="arbitrary",
                         minGapLat=f"{self.min_gap_lat_m}",
                         maxSpeedLat=f"{self.max_speed_lat_mps}")
        return attrs


TUM_MODELS: dict[str, KraussHuman] = {
    # trb_const_config.ini, [Strip Based Human Parameters]: a 2.6, b 4.5 (no separate
    # maximum braking, no MinSafeGap), StripWidth 0.1 m, ReactionTime N(1.5, 0.5)
    "tum_trb2024": KraussHuman(2.6, 4.5, 4.5, 0.0, 1.5, 0.5, 0.4, 0.2,
                               "TUM-VT/LaneFreeDrive@Paper-TRB-2024 trb_const_config.ini"),
    # trc_2025_default_settings.ini: a 1.5, b 1.5, MaxBrakeDeceleration 2.6, MinSafeGap 2 m,
    # StripWidth 0.05 m, ReactionTime N(1.5, 0.5)
    "tum_trc2025": KraussHuman(1.5, 1.5, 2.6, 2.0, 1.5, 0.5, 0.2, 0.2,
                               "TUM-VT/LaneFreeDrive@TRC-2025-HDVs_and_LFT "
                               "trc_2025_default_settings.ini"),
}


def reaction_times(n: int, model: KraussHuman, seed: int) -> np.ndarray:
    """(n,) reaction times, s: N(``tau_mean_s``, ``tau_sd_s``) from the run's seed (its own
    stream), clipped below at :data:`TAU_MIN_S`, rounded to 0.01 s."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x7A0]))
    tau = rng.normal(model.tau_mean_s, model.tau_sd_s, size=n)
    return np.round(np.maximum(tau, TAU_MIN_S), 2)


def vtype_id(base: str, tau_s: float) -> str:
    """The vType of a TUM human of size-class type ``base`` (``hdv_<k>``) with reaction
    time ``tau_s``: ``hdv_<k>_t<centiseconds>``."""
    return f"{base}_t{int(round(tau_s * 100)):03d}"
