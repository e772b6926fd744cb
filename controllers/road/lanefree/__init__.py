"""``flocking``: lane-free flocking for roads: car following, lateral purpose, cooperation.

The law keeps the seeds' form ``u_i = u_alpha + u_beta + u_gamma`` (Olfati-Saber 2006,
Algorithm 3; seed 000): interaction terms with the other CAVs (alpha-agents, connected:
they share their state, their applied acceleration and their lateral intention), with
the non-cooperating road users, the road edges and a stopped obstacle (beta-agents), and a
navigation term towards each CAV's own reference (gamma-agent: its desired speed along the
road and a lateral position it chooses). The axes are composed as road vehicles need:

**Longitudinal** (``u_s``): the navigation term and one interaction term per leader, of
which the smallest acts (the interaction terms are one-sided: they only ever slow a CAV,
as a repulsive potential ahead would)::

    u_s = min( k_v (v_des - v),                                   gamma: desired speed
               min_j  k_p (g_j - s0 - T_j v) + k_d (v_j - v) + k_ff,j a_j,   alpha/beta
               min_j  k_a (v_safe(g_j, v_j) - v) )                 approach bound

over the leaders ``j``: vehicles ahead that overlap the CAV laterally now or within
``anticipation_s`` (their lateral motion and its own), and CAVs that announced a move into
its band from ahead (*virtual leaders*, cooperation). ``g_j`` is the bumper-to-bumper gap,
``T_j`` the time gap (``time_gap_s`` behind a CAV, ``time_gap_hdv_s`` behind others),
``a_j`` the leader's applied acceleration (CAVs share it: ``k_ff = ff_gain``; others:
``k_ff = 0``). ``v_safe = -b tau + sqrt((b tau)^2 + v_j^2 + 2 b (g - s0))`` with the
comfortable deceleration ``b`` bounds the speed when closing in on a slow or stopped
vehicle from far (e.g. an obstacle), which the linear term alone does not. The spacing
error is clipped below at ``spacing_error_min_m`` so a cut-in at a safe gap does not cause
harsh braking, and the linear term acts only within ``spacing_error_max_m`` of the
desired gap (beyond it the approach bound alone brings the CAV in).

*String stability* (one step of actuation delay, ``dt`` = 0.1 s): for the linearised
CAV-behind-CAV law the low-frequency condition is ``k_p T^2 + 2 k_d T >= 2 (1 - k_ff)``
(here 0.6 x 0.55^2 + 2 x 0.95 x 0.55 = 1.23 >= 0.8, margin 0.43) and ``|G(e^{j w dt})| <= 1``
at all frequencies holds for ``k_p = 0.6, k_d = 0.95, k_ff = 0.6`` from T = 0.4 to 1.2 s with
one or two steps of delay (checked numerically; ``tests/test_lanefree_law.py`` checks a
20-CAV platoon's speed dip shrinking along the string). Behind human drivers
(no shared acceleration) the ACC gains ``k_p = 0.55, k_d = 1.6`` with T = 0.9 s keep
the condition (0.45 + 2.88 >= 2); at a shorter ``time_gap_hdv_s`` raise ``kd_hdv`` with it
(``LaneFreeParams.string_stability_margin_hdv()``; at 0.5 s at least 1.86 1/s).

**Lateral** (``u_d``): each CAV chooses a lateral target ``d*`` every ``replan_s`` (staggered)
by scoring candidate positions across the road ahead (``candidate_step_m`` apart, inside the
narrowest edges over the next ``lookahead_s`` of travel)::

    J(y) = v_offer(y) - c_move |y - d| + c_clear min(clearance(y), c) - c_nudge n(y)
           - c_order |y - y_pref(v_des)|

``v_offer(y)``: the speed the band at ``y`` offers (the slowest vehicle ahead in it, by the
same approach bound and time gap; ``v_des`` if free): CAVs overtake slower vehicles
through free lateral space and leave a blocked band (obstacle, narrowing) early.
``clearance(y)``: the lateral clearance at ``y`` to the vehicles alongside: as density
rises and every band offers the same speed, CAVs spread into the gaps, so rows form from
the vehicles' widths, not from slots. ``n(y)``: the desired-speed excess of CAVs close
behind in the band over this CAV's own desired speed, when this CAV drives at its desired
speed (nudging: a slower CAV that is the bottleneck makes room; in congestion nobody is
nudged). ``y_pref``: a weak
order by desired speed, slower to the right (a tie-breaker that keeps bands free for
overtaking at low density; 8 m of road weigh 0.8 m/s). The target changes only when the gain exceeds
``hysteresis_mps``. Then a PD navigation term with barrier repulsion::

    u_d = k_y (d* - d) - c_y v_d + sum_j repulsion(clearance_ij)

bounded (boundary control, as TrafficFluid's boundary controllers) so that the CAV can stop
laterally, at ``a_lat_bound``, before coming closer than ``lateral_clearance_m`` to a vehicle
alongside (longitudinally overlapping, with a closing-speed buffer, or one it could not be
followed by or follow safely) or ``edge_margin_m`` to the road edge ahead.

The tie-breakers (clearance, order) weigh only for a CAV near its desired speed (their
weight falls from 1 at 95 % to 0 at 75 % of it): in dense traffic a lateral move must pay
in speed.

**Cooperation** (CAVs are connected): a CAV whose move pays in speed
(``urgent_gain_mps``) or leaves a blocked band, and is still more than half its width from
its target, announces
its target band; a CAV behind it in that band treats it as a virtual leader projected into
its own lane-free position, with time gap ``coop_time_gap_s``, braking at most at
``yield_decel_mps2`` (politeness); a CAV ahead of it does nothing, so the mover slots in
behind: it treats the vehicles in its target band that are ahead of it as leaders at the
same time gap, braking at most at the comfortable deceleration. A CAV behind the mover that
would have to brake harder than ``yield_decel_mps2`` to let it in, or is already closer
behind it than the gap the mover needs beside it, goes on instead, and the mover, which
computes the same test, falls in behind it (zipper order: the one further ahead goes first
unless the other cannot let it in; nothing waits for a vehicle that waits for it, and the
mover waits only for a vehicle behind that moves, faster than 1 m/s). Human
drivers are not cooperative: a slow or stopped human driver whose own band is blocked
ahead is given the same yield by the CAVs behind it in the neighbouring bands, so it can
merge out (nobody traps it).

**Where the law sees others** (``law._entering``): a vehicle still outside the road (on an
on-ramp) counts as on the road, at its nearest inside position, once it is within
``entry_reach_m`` of the edge or would reach it within ``entry_horizon_s`` at its lateral
speed towards the road (from its positions: a ramp vehicle reports none across its own
lane); a moving vehicle whose body leaves the narrowest edges of the next
``max(squeeze_min_m, squeeze_s * v)`` metres counts at its nearest inside position there
(a human driver that a narrowing will squeeze in: CAVs make room before it is pushed in;
also one that hugs the edge just before an abrupt step).

All terms are computed per CAV over a fixed window of neighbours in road order (no N x N
array), in compiled kernels (numba; :mod:`.kernels`) that give what the vectorised numpy
form of the law gave, to round-off (``tests/test_exactness.py``); memory across steps
(targets, last accelerations, speeds of others) is keyed by vehicle id.

Modules: :mod:`.params` (:class:`LaneFreeParams`), :mod:`.law` (:class:`LaneFreeFlocking`),
:mod:`.kernels` (the compiled loops).
"""

from .law import LaneFreeFlocking
from .params import LaneFreeParams

__all__ = ["LaneFreeFlocking", "LaneFreeParams"]
