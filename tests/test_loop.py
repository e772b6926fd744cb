"""The simulation loop without SUMO: the SUMO-free road world drives the whole loop.

Phases run in order with hooks around each; the phase timer splits the cost; a law
that breaks the protocol is named in one error; the safety layer keeps a senseless law
(full throttle) collision-free, and without it our geometric check counts the crashes,
the stopped obstacle included; jam figures are zero in free flow and not in a jam; the
road world integrates commanded speeds exactly and inserts vehicles only with room.

Laws under test live in a module written to a temporary folder on ``sys.path`` and are
selected as ``controller.kind = "loop_laws:Class"``, as a user's would be. Every test
runs in well under a second (0.1 s steps).
"""

from __future__ import annotations

import sys
import textwrap
import time

import numpy as np
import pytest

from controllers.layers.constraints import ActuatorLimits
from controllers.layers.safety import SafetyConfig, SafetyLayer
from cosim.config.scenario import load_scenario
from cosim.demand.plan import DemandPlan, _Vehicle
from cosim.demand.spec import HDV_TAU_S, MIN_GAP_M
from cosim.errors import CosimError
from cosim.road.geometry import road_geometry
from cosim.road.spec import NetworkSpec
from cosim.sim.loop import PHASES, Loop, PhaseTimer
from cosim.sim.road_world import RoadWorld
from cosim.sim.runner import run_scenario

DT = 0.1

LAWS = '''
import time
import numpy as np

class Zero:
    """Keeps every speed: u = 0."""
    def compute(self, obs):
        return np.zeros((len(obs.q), 2))

class Throttle:
    """Senseless: full throttle (10 m/s^2, beyond the actuator box), never steers."""
    def compute(self, obs):
        return np.tile([10.0, 0.0], (len(obs.q), 1))

class Stop:
    """Brakes to a standstill and stays there."""
    def compute(self, obs):
        return np.column_stack([-4.0 * np.ones(len(obs.q)), np.zeros(len(obs.q))])

class Wavy:
    """A command that changes every step (exact integration test)."""
    def compute(self, obs):
        a = 1.5 * np.sin(0.7 * obs.t + np.arange(len(obs.q)))
        return np.column_stack([a, 0.8 * np.cos(0.9 * obs.t) * np.ones(len(obs.q))])

class BadShape:
    def compute(self, obs):
        return np.zeros((len(obs.q), 3))

class NaNLaw:
    def compute(self, obs):
        u = np.zeros((len(obs.q), 2))
        u[0, 0] = np.nan
        return u

class Slow:
    """Zero, 3 ms of wall time per call (sleeping: no CPU)."""
    def compute(self, obs):
        time.sleep(0.003)
        return np.zeros((len(obs.q), 2))
'''


@pytest.fixture(scope="module", autouse=True)
def loop_laws(tmp_path_factory):
    """``loop_laws`` importable for the module's tests, as a user's module would be."""
    folder = tmp_path_factory.mktemp("user_laws")
    (folder / "loop_laws.py").write_text(textwrap.dedent(LAWS))
    sys.path.insert(0, str(folder))
    import loop_laws as mod

    yield mod
    sys.path.remove(str(folder))
    sys.modules.pop("loop_laws", None)


def _scenario(name: str, **over):
    base = {"scenario.world": "road", "scenario.duration_s": 40.0, "scenario.warmup_s": 5.0,
            "scenario.interval_s": 10.0}
    return load_scenario(name, {**base, **{k.replace("__", "."): v for k, v in over.items()}})


def _run(name: str, **over) -> dict:
    return run_scenario(_scenario(name, **over))


def _vehicle(vid: str, *, s: float | None = None, d: float = 0.0, v: float = 20.0,
             desired: float = 25.0, cav: bool = True, depart: float = 0.0,
             length: float = 4.5, width: float = 1.8) -> _Vehicle:
    return _Vehicle(vid=vid, vtype="car", route="main", depart=depart, speed=desired,
                    factor=1.0, depart_pos="0", depart_lat=None, depart_lane="0",
                    depart_speed=str(v), is_cav=cav, length_m=length, width_m=width, lat_m=d,
                    centre_s_m=s, v0_mps=v)


def _world(vehicles, *, ring: bool = False, length: float = 1000.0) -> RoadWorld:
    spec = (NetworkSpec(kind="ring", circumference_m=length) if ring
            else NetworkSpec(kind="straight", length_m=length))
    return RoadWorld(road_geometry(spec), DemandPlan(list(vehicles), "test"), DT)


# --------------------------------------------------------------------------------------
# Phases and hooks
# --------------------------------------------------------------------------------------


def _trace(loop: Loop) -> list:
    events = []
    for phase in PHASES:
        for when in ("before", "after"):
            loop.hooks.add(phase, lambda st, p=phase, w=when: events.append((st.k, w, p)), when)
    return events


def test_phases_run_in_order_with_hooks_before_and_after_each(loop_laws):
    world = _world([_vehicle("cav.0", s=100.0), _vehicle("hdv.0", s=200.0, cav=False)],
                   ring=True)
    loop = Loop(world, loop_laws.Zero(), ActuatorLimits())
    events = _trace(loop)
    loop.run(3)
    expected = [(k, w, p) for k in range(3) for p in PHASES for w in ("before", "after")]
    assert events == expected
    # SUMO drives the CAVs (no law): the law's phases are skipped, not reordered
    loop = Loop(_world([_vehicle("cav.0", s=100.0)], ring=True), None, ActuatorLimits())
    events = _trace(loop)
    loop.run(2)
    assert [p for k, w, p in events if k == 1 and w == "before"] == [
        "advance", "observe", "record"]


def test_a_record_hook_sees_the_state_after_the_step(loop_laws):
    world = _world([_vehicle("cav.0", s=100.0, v=20.0), _vehicle("cav.1", s=300.0, v=15.0)],
                   ring=True)
    loop = Loop(world, loop_laws.Wavy(), ActuatorLimits())
    seen = []

    def record(st):
        now = world.observe()
        assert st.t == pytest.approx(world.time) and st.t == pytest.approx((st.k + 1) * DT)
        np.testing.assert_array_equal(st.state.s, now.s)
        np.testing.assert_array_equal(st.state.v, now.v)
        seen.append((st.k, st.state.v.copy(), st.v_next.copy()))

    loop.hooks.add("record", record)
    loop.hooks.add("advance", lambda st: seen.append(("before", world.time)), "before")
    loop.run(20)
    assert seen[0] == ("before", 0.0)
    recs = [x for x in seen if x[0] != "before"]
    assert len(recs) == 20
    for (_, v_now, _), (_, _, v_cmd_prev) in zip(recs[1:], recs[:-1], strict=True):
        np.testing.assert_allclose(v_now, v_cmd_prev, rtol=0, atol=1e-12)  # applied next step


# --------------------------------------------------------------------------------------
# The road world's kinematics and entrance
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("ring", [False, True])
def test_road_world_integrates_commanded_speed_exactly(loop_laws, ring):
    """s += v_next dt, v = v_next, d = d_next, to rounding, over 100 steps; on the ring
    across the seam."""
    world = _world([_vehicle("cav.0", s=950.0 if ring else 50.0, v=20.0)], ring=ring,
                   length=1000.0 if ring else 3000.0)
    loop = Loop(world, loop_laws.Wavy(), ActuatorLimits())
    log = []
    loop.hooks.add("record", lambda st: log.append(
        (st.state.s[0], st.state.v[0], st.state.d[0], st.v_next[0], st.d_next[0])))
    loop.run(100)
    s, v, d, v_cmd, d_cmd = (np.array(x) for x in zip(*log, strict=True))
    ds = np.diff(s)
    if ring:
        assert s.min() < 50.0 < 900.0 < s.max()  # crossed the seam
        ds = np.mod(ds, 1000.0)
    np.testing.assert_allclose(ds, v_cmd[:-1] * DT, rtol=0, atol=1e-9)
    np.testing.assert_allclose(v[1:], v_cmd[:-1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(d[1:], d_cmd[:-1], rtol=0, atol=1e-12)
    assert np.ptp(v) > 2.0 and np.ptp(d) > 0.5  # the commands really varied


def test_road_world_inserts_vehicles_only_with_room():
    """Five human drivers due at t = 0 in one band at 20 m/s: the first enters, the others
    wait (pending) and enter in turn, each once the gap ahead is at least s0 + v0 T =
    22.5 m and it could stop behind the vehicle ahead."""
    band = [_vehicle(f"hdv.{k}", d=0.3 * (k % 2), v=20.0, desired=20.0, cav=False)
            for k in range(5)]
    world = _world(band, length=2000.0)
    need = MIN_GAP_M + 20.0 * HDV_TAU_S
    world.step()
    assert world.departed_now == ["hdv.0"] and world.pending() == 4
    entered = {"hdv.0": world.time}
    for _ in range(100):
        world.step()
        snap = world.observe()
        for vid in world.departed_now:
            entered[vid] = world.time
            r = snap.ids.index(vid)
            assert snap.s[r] == pytest.approx(0.5 * snap.length[r])  # rear at the start
            ahead = np.array([k for k in range(snap.n) if k != r])
            gaps = snap.s[ahead] - 0.5 * snap.length[ahead] - (snap.s[r] + 0.5 * snap.length[r])
            g, leader = gaps.min(), ahead[np.argmin(gaps)]
            assert g >= need - 1e-9, (vid, g)
            # it could stop behind its leader braking at the emergency deceleration
            assert snap.v[r] ** 2 <= snap.v[leader] ** 2 + 2 * 9.0 * (g - MIN_GAP_M)
            assert g < 2 * need  # and did not wait for much more than room
    assert list(entered) == [f"hdv.{k}" for k in range(5)] and world.pending() == 0
    times = np.array(list(entered.values()))
    assert np.all(np.diff(times) > 1.0)  # each waited (~1.2 s of travel at 20 m/s)


# --------------------------------------------------------------------------------------
# The phase timer
# --------------------------------------------------------------------------------------


def test_phase_timer_accumulates_time_per_phase(loop_laws):
    world = _world([_vehicle(f"cav.{k}", s=100.0 * k, d=0.0) for k in range(5)], ring=True)
    loop = Loop(world, loop_laws.Slow(), ActuatorLimits(),
                SafetyLayer(SafetyConfig(dt=DT)))
    loop.run(2)  # first calls load compiled kernels (numba): not what is timed here
    timer = PhaseTimer(loop.hooks)
    t0 = time.perf_counter()
    loop.run(20)
    total = time.perf_counter() - t0
    assert set(timer.wall_s) == set(PHASES) and set(timer.cpu_s) == set(PHASES)
    assert timer.wall_s["control"] >= 20 * 0.003  # the law's sleep lands in "control"
    assert timer.cpu_s["control"] < 0.5 * timer.wall_s["control"]  # sleeping is not CPU
    others = sum(w for p, w in timer.wall_s.items() if p != "control")
    assert others < timer.wall_s["control"]
    assert all(w >= 0 for w in timer.wall_s.values())
    assert sum(timer.wall_s.values()) <= total


# --------------------------------------------------------------------------------------
# A law breaking the protocol
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("law, message", [
    ("BadShape", r"BadShape\.compute returned shape \(#, 3\), expected \(#, 2\)"),
    ("NaNLaw", r"NaNLaw\.compute returned a non-finite acceleration"),
])
def test_a_law_returning_a_wrong_shape_or_nan_is_named(loop_laws, law, message):
    loop = Loop(_world([_vehicle("cav.0", s=10.0), _vehicle("cav.1", s=500.0)], ring=True),
                getattr(loop_laws, law)(), ActuatorLimits())
    with pytest.raises(CosimError, match=message.replace("#", "2") + r" \(step 0, t = 0\.1 s\)"):
        loop.run(5)
    with pytest.raises(CosimError, match=message.replace("#", "30")):  # 30 CAVs on the ring
        _run("ring", controller__kind=f"loop_laws:{law}")


# --------------------------------------------------------------------------------------
# The safety layer keeps a senseless law collision-free; without it we count crashes
# --------------------------------------------------------------------------------------


#: The open road busier than the built-in default, so that full-throttle CAVs reach the
#: humans ahead within the 40 s whatever the seed's departures.
BUSY = {"demand__inflow_vph": 3600.0}


@pytest.mark.parametrize("name", ["ring", "default"])
def test_safety_keeps_full_throttle_collision_free(name):
    """Full throttle (u = (10, 0) m/s^2) among human drivers: a 1 km ring with 60 veh/km
    and a 1 km open road with 3600 veh/h, half of them CAVs, 40 s."""
    over = BUSY if name == "default" else {}
    s = _run(name, controller__kind="loop_laws:Throttle", **over).summary.iloc[0]
    assert s["collisions_geometric_cav"] == 0 and s["collisions_geometric_hdv_only"] == 0
    assert s["boundary_vehicle_steps"] == 0
    assert s["safety_speed_activations"] > 10  # it was the layer, not luck
    assert s["clip_rate_loop_acceleration_box"] > 0.5  # the actuator box clipped 10 to 2.6 m/s^2


@pytest.mark.parametrize("name", ["ring", "default"])
def test_without_safety_full_throttle_collides_and_is_counted(name):
    over = BUSY if name == "default" else {}
    res = _run(name, controller__kind="loop_laws:Throttle", safety__enabled=False, **over)
    s = res.summary.iloc[0]
    assert s["collisions_geometric_cav"] > 0
    assert s["safety_speed_activations"] == 0
    col = res.collisions
    assert len(col) == s["collisions_geometric_cav"] + s["collisions_geometric_hdv_only"]
    assert set(col["source"]) == {"geometric"} and (col["kind"] == "cav").any()


def test_the_obstacle_is_in_the_collision_check():
    """CAVs keep their speed (u = 0) towards a stopped vehicle across the whole road:
    with the safety layer off they drive into it and each crash is counted with it."""
    obstacle = {"obstacle__s_m": 350.0, "obstacle__d_m": 0.0, "obstacle__length_m": 4.5,
                "obstacle__width_m": 9.8, "demand__cav_share": 1.0}
    res = _run("default", controller__kind="loop_laws:Zero", safety__enabled=False, **obstacle)
    s = res.summary.iloc[0]
    col = res.collisions
    with_obstacle = col[(col["a"] == "obstacle") | (col["b"] == "obstacle")]
    assert len(with_obstacle) >= 5
    assert s["collisions_geometric_cav"] >= len(with_obstacle)
    # the same with the safety layer: every CAV stops behind it, nobody touches it
    s = _run("default", controller__kind="loop_laws:Zero", **obstacle).summary.iloc[0]
    assert s["collisions_geometric_cav"] == 0 and s["safety_speed_activations"] > 0


# --------------------------------------------------------------------------------------
# Jam figures
# --------------------------------------------------------------------------------------


def test_jam_figures_are_zero_in_free_flow():
    s = _run("ring", controller__kind="loop_laws:Zero", scenario__duration_s=80.0,
             demand__cav_share=1.0, demand__ring_density_vpkm=30.0).summary.iloc[0]
    assert s["max_standstill_s"] == 0.0 and s["vehicles_stopped_long"] == 0
    assert s["blocked_windows"] == 0 and not s["gridlock"]
    assert s["space_mean_speed_mps"] > 20.0


def test_jam_figures_see_a_ring_that_stopped():
    """Every CAV brakes to a standstill within 7 s and stays: 73 s standing, each of the
    30 vehicles stopped longer than 30 s, and each of the 3 cross-sections blocked in
    both 30 s windows after the 10 s warm-up."""
    s = _run("ring", controller__kind="loop_laws:Stop", scenario__duration_s=80.0,
             scenario__warmup_s=10.0, demand__cav_share=1.0,
             demand__ring_density_vpkm=30.0).summary.iloc[0]
    assert s["max_standstill_s"] == pytest.approx(80.0 - 7.0, abs=1.0)
    assert s["vehicles_stopped_long"] == 30
    assert s["blocked_windows"] == 3 * 2 and s["gridlock"]
    assert s["space_mean_speed_mps"] < 0.1


def test_jam_figures_see_a_queue_behind_a_blocked_road():
    """A stopped vehicle across the whole open road: everyone queues behind it (the
    safety layer stops the CAVs, the IDM the human drivers), nobody passes it."""
    s = _run("default", controller__kind="loop_laws:Zero", scenario__duration_s=100.0,
             scenario__warmup_s=20.0, obstacle__s_m=850.0, obstacle__length_m=4.5,
             obstacle__width_m=9.8).summary.iloc[0]
    assert s["collisions_geometric_cav"] == 0 and s["collisions_geometric_hdv_only"] == 0
    assert s["max_standstill_s"] > 45.0
    assert s["vehicles_stopped_long"] >= 5
    assert s["blocked_windows"] >= 2 and s["gridlock"]


@pytest.mark.parametrize("name", ["default", "obstacle", "ring", "varying_width"])
def test_the_loops_observation_equals_the_validating_constructors(name):
    """The loop builds its observation with ``Observation.trusted`` (no checks, no
    copies); the validating constructor, given the same fields, builds the same one: the
    same values, dtypes and shapes in every field (CAVs only, and with sensed vehicles)."""
    from dataclasses import fields

    from controllers.observation import Observation

    seen: list = []
    over = {"scenario.world": "road", "scenario.duration_s": 20.0, "scenario.warmup_s": 1.0,
            "scenario.interval_s": 10.0, "demand.cav_share": 0.7}

    def hooks(loop):
        loop.hooks.add("reference", lambda st: seen.append(st.obs))

    run_scenario(load_scenario(name, over), hooks=hooks)
    assert len(seen) > 50 and any(len(o.others_q) for o in seen)
    for obs in seen[::7]:
        again = Observation(**{f.name: getattr(obs, f.name) for f in fields(Observation)})
        for f in fields(Observation):
            a, b = getattr(obs, f.name), getattr(again, f.name)
            if isinstance(a, np.ndarray):
                assert a.dtype == b.dtype and a.shape == b.shape, f.name
                assert np.array_equal(a, b), f.name
            else:
                assert a == b or a is b, f.name


def test_a_trusted_observation_skips_the_finite_check_only_when_its_builder_checked():
    """``state_finite`` marks an observation whose builder (the loop's ``cav_columns``)
    saw every entry of q and p finite; the loop passes what the kernel found, so a NaN
    from the world still stops the law with the agent named."""
    from controllers.observation import InvalidStateError, Observation
    from cosim.sim.kernels import cav_columns

    def columns(v):
        s = np.array([10.0, 20.0, 30.0])
        d, vl, ln, wd = np.zeros(3), np.zeros(3), np.full(3, 4.5), np.full(3, 1.8)
        return cav_columns(np.arange(3, dtype=np.int64), s, d, v, vl, ln, wd,
                           np.full(3, np.nan), 30.0, 0.1, 9.0, 5.0)

    assert columns(np.array([20.0, 21.0, 22.0]))[-1] is True
    for bad in (np.nan, np.inf):
        q, p, *_, finite = columns(np.array([20.0, bad, 22.0]))
        assert finite is False
        obs = Observation.trusted(state_finite=finite, q=q, p=p, ids=np.array(["a", "b", "c"],
                                                                              dtype=object))
        with pytest.raises(InvalidStateError, match="'b'"):
            obs.check_finite()
    q = np.array([[0.0, np.nan]])
    Observation.trusted(state_finite=True, q=q, p=np.zeros((1, 2))).check_finite()  # trusted
    with pytest.raises(InvalidStateError):
        Observation.trusted(q=q, p=np.zeros((1, 2))).check_finite()
