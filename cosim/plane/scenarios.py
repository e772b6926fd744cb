"""Reproductions of the seeds' experiments in the plane world.

Each function builds a :class:`~cosim.plane.world.PlaneWorld` with the seed's
parameters; ``run_plane_scenario(name)`` runs it. From the shell:
``cosim plane seed000`` or ``cosim plane seed001 --saturation 10``.
"""

from __future__ import annotations

import math

import numpy as np

from controllers.layers.constraints import AccelerationBox, ConstrainedController, SpeedSaturation
from controllers.observation import Circles, Walls
from controllers.plane.olfati_saber import OlfatiSaberController
from controllers.plane.params import FlockingParams
from controllers.plane.references import VirtualLeader
from cosim.plane.world import PlaneResult, PlaneWorld


def seed000_params() -> FlockingParams:
    """Seed 000 CONSTANTS.m: d = 6, r = 1.2 d, d' = 12, d'' = 0.5 d, gains, dynamic weights.

    The paper's law exactly (``barrier_floor="none"``): no saturated barrier.
    """
    d = 6.0
    return FlockingParams(
        d=d,
        r=1.2 * d,
        d_beta=12.0,
        r_beta=1.2 * 12.0,
        d_wall=0.5 * d,
        r_wall=1.2 * 0.5 * d,
        epsilon=0.1,
        a=5.0,
        b=5.0,
        h_alpha=0.2,
        h_beta=0.9,
        c1_alpha=50.0,
        c2_alpha=2 * math.sqrt(50.0),
        c1_beta=100.0,
        c2_beta=2 * math.sqrt(100.0),
        c1_wall=150.0,
        c2_wall=2 * math.sqrt(150.0),
        c1_gamma=(5.0, 2.0),
        c2_gamma=(2 * math.sqrt(5.0), 2 * math.sqrt(2.0)),
        dynamic_weights=True,
        barrier_floor="none",
    )


def seed000_world(
    seed: int = 45,
    n_agents: int = 10,
    lateral_leader_speed_mps: float = 0.0,
    integrator: str = "euler",
) -> PlaneWorld:
    """Seed 000: 10 CAVs on a 50 m wide road (edges at +-25 m), obstacle R = 10 at (55, 0),
    virtual leader from (50, 0) at 10 m/s; dt = 0.01 s.

    Initial positions as CONSTANTS.m: x uniform in [-75, 0], y uniform in
    [-25, 25], at rest (numpy's generator with ``seed``, not MATLAB's rng(45)).
    ``lateral_leader_speed_mps`` gives the "dynamic virtual leader" variant.
    """
    rng = np.random.default_rng(seed)
    q0 = np.column_stack([rng.random(n_agents) * -75.0, rng.random(n_agents) * 50.0 - 25.0])
    p0 = np.zeros_like(q0)
    prm = seed000_params()
    leader = VirtualLeader(q=[50.0, 0.0], p=[10.0, lateral_leader_speed_mps])
    return PlaneWorld(
        q0,
        p0,
        OlfatiSaberController(prm),
        dt=0.01,
        reference=leader,
        circles=Circles([[55.0, 0.0]], [10.0]),
        walls=Walls([[0.0, -25.0], [0.0, 25.0]], [[0.0, 1.0], [0.0, -1.0]]),
        integrator=integrator,
        lattice_d=prm.d,
        lattice_r=prm.r,
    )


def seed001_params() -> FlockingParams:
    """Seed 001 Algorithm 2: c1 = c2 = 0.1 for the goal; unit alpha gains.

    Seed 001 does not state d and r (its text reads "c = X"); we take OS06's
    d = 7, r = 1.2 d, epsilon = 0.1, a = b = 5, h = 0.2. It has no obstacles, so
    ``barrier_floor="none"`` (the paper's law) only states that no floor is used.
    """
    return FlockingParams(
        d=7.0,
        r=8.4,
        epsilon=0.1,
        a=5.0,
        b=5.0,
        h_alpha=0.2,
        c1_alpha=1.0,
        c2_alpha=1.0,
        c1_gamma=0.1,
        c2_gamma=0.1,
        barrier_floor="none",
    )


def seed001_world(
    seed: int = 1,
    n_agents: int = 50,
    speed_limit_mps: float | None = None,
    accel_limit_mps2: float | None = None,
    m: int = 2,
    integrator: str = "euler",
) -> PlaneWorld:
    """Seed 001: 50 agents from positions in [0, 100]^m and velocities in [-100, 100]^m,
    goal at q_r = 100 moving with p_r = 20 per axis (f_r = 0), c1 = c2 = 0.1, dt = 0.01 s.

    ``speed_limit_mps`` adds seed 003's sat() (10 m/s in seed 001's comparison);
    ``accel_limit_mps2`` bounds ``||u||`` (actuator saturation).
    """
    rng = np.random.default_rng(seed)
    q0 = rng.uniform(0.0, 100.0, (n_agents, m))
    p0 = rng.uniform(-100.0, 100.0, (n_agents, m))
    prm = seed001_params()
    layers = []
    if speed_limit_mps is not None:
        layers.append(SpeedSaturation(p_max=speed_limit_mps))
    if accel_limit_mps2 is not None:
        big = 1e9
        layers.append(
            AccelerationBox(long_min=-big, long_max=big, lat_max=big, a_max=accel_limit_mps2)
        )
    controller = ConstrainedController(OlfatiSaberController(prm), layers)
    leader = VirtualLeader(q=np.full(m, 100.0), p=np.full(m, 20.0))
    return PlaneWorld(
        q0,
        p0,
        controller,
        dt=0.01,
        reference=leader,
        integrator=integrator,
        lattice_d=prm.d,
        lattice_r=prm.r,
        record_every=10,
        metrics_every=10,
    )


SCENARIOS = {
    "seed000": (seed000_world, 15.0),
    "seed001": (seed001_world, 32.0),
}
#: One line per plane scenario (``cosim list``, ``cosim plane --help``).
DESCRIPTIONS = {
    "seed000": "Olfati-Saber Algorithm 3 (paper's law): 10 agents pass a circular obstacle "
               "on a 50 m wide road behind a moving leader, 15 s",
    "seed001": "Algorithm 2: 50 agents track a moving goal, step 0.01 s; --saturation caps "
               "the speed (m/s), 32 s",
}


def obstacles_meta(world: PlaneWorld) -> dict:
    """The world's obstacles as JSON-ready lists (for meta.json and the figures).

    Keys (only those present): ``circles`` with ``centres_m`` (K, m) and ``radii_m`` (K,);
    ``walls`` with ``points_m`` (K, m) and unit ``normals`` (K, m) into the free space;
    ``road_edges_m`` the constant (right, left) lateral edges, m.
    """
    out: dict = {}
    if world.circles is not None and len(world.circles.radii):
        out["circles"] = {
            "centres_m": world.circles.centres.tolist(),
            "radii_m": world.circles.radii.tolist(),
        }
    if world.walls is not None and len(world.walls.points):
        out["walls"] = {
            "points_m": world.walls.points.tolist(),
            "normals": world.walls.normals.tolist(),
        }
    if world.road_edges is not None and not callable(world.road_edges):
        out["road_edges_m"] = np.asarray(world.road_edges, dtype=float).ravel()[:2].tolist()
    return out


def run_plane_scenario(
    name: str, seed: int | None = None, duration_s: float | None = None, **kwargs
) -> PlaneResult:
    """Run a built-in plane scenario by name and return its result (with meta)."""
    if name not in SCENARIOS:
        raise KeyError(f"unknown plane scenario {name!r}; choose from {sorted(SCENARIOS)}")
    build, default_duration = SCENARIOS[name]
    if seed is not None:
        kwargs["seed"] = seed
    world = build(**kwargs)
    world.run(default_duration if duration_s is None else duration_s)
    meta = {"scenario": name, "duration_s": duration_s or default_duration, **kwargs}
    meta["obstacles"] = obstacles_meta(world)
    law = getattr(world.controller, "law", world.controller)
    if hasattr(law, "params"):
        meta["params"] = law.params
    if hasattr(world.controller, "clip_stats"):
        meta["clip_rates"] = world.controller.clip_stats()
    return world.result(meta)
