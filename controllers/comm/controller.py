"""Communication layer (seed 001): each agent acts on what it has received.

Seed 001 (Johnson, "Multi-waypoint flocking with delays and saturation") lets
every agent broadcast its state at its own update instants; a message reaches
each agent within the communication radius ``r_comm`` after a bounded delay,
and the receiver computes its control from its own state and the last
received states of the others (the HIOA ``send_i``/``recv_ij`` model, Figs.
21-22). :class:`CommunicatingController` wraps any control law with
``compute(Observation) -> u (N, m)`` and makes it act that way:

* **clocks**: ``"synchronous"``: every agent updates at ``k * period_s`` on a
  common clock; ``"asynchronous"``: agent ``i`` has its own clock with a
  random phase in ``[0, T_i)`` (counted from the instant it first appears) and
  its own period ``T_i = period_s (1 + period_jitter U(-1, 1))`` (clock drift).
  Update instants are taken at the first world step at or after them.
* **send**: at its update instant an agent broadcasts ``(q, p, t_send)``. Every
  other present agent closer than ``r_comm_m`` at send time is a receiver
  (strict ``<``, seed 001's ``N_c(i, q)``); each (sender, receiver) copy is lost
  with probability ``loss_prob`` and otherwise delivered after a delay drawn
  uniformly in ``[delay_min_s, delay_max_s]`` (usable from the first step at
  or after ``t_send + delay``; zero delay: in the same step).
* **buffer**: per receiver and sender (keyed by vehicle ids, so agents may
  enter and leave) only the delivered message with the latest ``t_send`` is
  kept (an older one arriving late is discarded). A message is dropped when
  its age ``t - t_send`` exceeds ``expiry_s``. Messages of an agent that left
  stay in the others' buffers until they expire (nobody tells them).
* **control**: at its update instant agent ``i`` evaluates the wrapped law on
  its own view (its true ``q_i``, ``p_i`` and the buffered states of the
  others) and holds the result until its next instant (zero-order hold, both
  modes; the seed's agents set ``u_i`` only in ``send_i``). Before its first
  instant an agent's command is zero. With ``extrapolate=True`` (dead
  reckoning, an addition to seed 001) a buffered state is moved forward to the
  update instant with its own velocity. Everything not communicated (the
  reference/leader, obstacles, walls, road edges, sensed non-cooperating
  vehicles) is taken from the true observation at the update instant.

A law with memory of its own agents (``memory_per_agent = True``, as the lane-free law:
lateral targets and their hysteresis, yields, the past speeds of sensed vehicles) gets
one copy per agent when it is called on per-agent views: agent ``i``'s copy sees only
``i``'s views, so its memory is what agent ``i`` remembered (one shared instance would be
called once per agent and step, and would take every agent for a newcomer in every call).
A copy is made from the law as it was at :meth:`CommunicatingController.reset` and is
dropped when its agent leaves. A step whose views are all the truth calls the shared law.

Per step the order is: clocks, send, deliver, expire, compute. With zero delay,
no loss, ``r_comm`` covering the flock and ``period_s <= dt`` (synchronous)
every view is the true state and the wrapped law is reproduced exactly.
Randomness (loss, delays, asynchronous clocks) comes from one
``numpy.random.default_rng(seed)`` drawn in a fixed order, so a run is
deterministic given the seed and the sequence of observations.

Evaluating the law on per-agent views
-------------------------------------
A view is agent ``i`` (first row) followed by the ``k_i`` states in its buffer.
The wrapped law must be permutation-equivariant (an agent's command depends on
the set of rows, not on their order or index), as OS06's law is. Instead of
calling the law once per agent, the ``B`` views due at a step are laid side by
side along axis 0 (axis 1 on a ring road), each block translated so that
blocks lie ``block_gap_m`` apart, and the law is called **once** on the
disjoint union (``R = B + sum k_i`` rows); row ``i`` of block ``i`` is agent
``i``'s command. This needs a *local* and *translation-invariant* law (rows
further apart than its range do not interact; positions enter only relative to
other rows, the leader and obstacles), as OS06's law is; otherwise use
``batching="loop"``. The leader and the road edges become per-row arrays (the
ego's, shifted with its block); circles and sensed vehicles are replicated per
block; walls must be parallel to the block axis. ``block_gap_m`` must exceed
the law's largest interaction range (OS06 seed 001: r = 8.4 m). Translation
changes relative positions by rounding only (about 1e-16 of the union's span).

Cost per step with ``B`` updating agents holding ``k_i`` messages: ids and
clocks O(N) (a Python dict lookup per agent); send O(B N) with a dense table
when ``B N <= 20 000``, else O(N log N + messages) with KD-trees;
deliver/expire O(E log E) with ``E`` the buffered messages (``E <= sum k_i``,
a sort); building the views O(R) (plus one Python tuple per row for the
ghost ids); one law call on ``R`` rows. For
OS06's law the pair search is O(R log R) but every view's internal pairs are
evaluated (neighbour-to-neighbour pairs are computed and discarded), so the
pair work is O(sum_i k_i^2) instead of O(sum_i k_i): about ``k`` times the
plain law for a lattice with ``k`` neighbours (``k ~ 6`` in 2-D). With
``r_comm = inf`` every view holds all ``N - 1`` others (R ~ N^2), so keep
``r_comm`` near the law's range for large N. When every agent is due and every
view is the complete, fresh true state, the law is called on the true
observation instead (exact; the ideal configuration costs one plain call).
``batching="loop"`` (and obstacles the union cannot translate: walls not
parallel to the block axis, a 1-D ring) calls the law once per updating agent:
``B`` calls of O(k_i) rows each.

Use with constraint layers: put stateful or per-step layers (speed saturation,
acceleration box, jerk limit) *outside* the wrapper,
``ConstrainedController(CommunicatingController(law, cfg), layers)``, so that
they act on the held command every step and keep their per-id memory.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from controllers.comm.config import CommConfig, CommStats
from controllers.comm.messages import Clocks, Messages
from controllers.comm.views import Views
from controllers.errors import ParameterError
from controllers.neighbours import cross_pairs
from controllers.observation import Observation

_DENSE_SEND_MAX = 20_000  # sender x agent pairs below which sending uses a dense table
BATCHING = ("auto", "union", "loop")


class CommunicatingController:
    """Wrap a control law so that each agent acts on received, delayed, held information.

    ``compute(obs) -> u`` (N, m) in m/s^2, called once per world step with
    increasing ``obs.t``. See the module docstring for the model and the cost.

    Args:
        law: any object with ``compute(Observation) -> (N, m)``; must be
            permutation-equivariant, and for the union batching local and
            translation-invariant (see module docstring).
        config: :class:`CommConfig` (default: ideal synchronous, T = 0.1 s).
        batching: "auto" (one union call when the observation allows it,
            else one call per updating agent), "union" (error if not
            possible) or "loop".
        block_gap_m: gap between views in a union call, m; must exceed the
            law's largest interaction range.
    """

    def __init__(
        self,
        law,
        config: CommConfig | None = None,
        *,
        batching: str = "auto",
        block_gap_m: float = 1000.0,
    ) -> None:
        if batching not in BATCHING:
            raise ParameterError(f"batching must be one of {BATCHING}, got {batching!r}")
        if not block_gap_m > 0:
            raise ParameterError(f"block_gap_m must be > 0 m, got {block_gap_m!r}")
        self.law = law
        self.config = config or CommConfig()
        self.batching = batching
        self.block_gap_m = float(block_gap_m)
        self.name = f"comm({getattr(law, 'name', type(law).__name__)})"
        self.reset()

    def reset(self) -> None:
        """Forget all agents, clocks, messages and counters; reseed the generator."""
        self.rng = np.random.default_rng(int(self.config.seed))
        self.stats = CommStats()
        self._slot_of: dict = {}
        self._id_of: list = []
        self._clk = Clocks()
        self._u: np.ndarray | None = None
        self._m: int | None = None
        self._buf: Messages | None = None
        self._pending: Messages | None = None
        reset_law = getattr(self.law, "reset", None)
        if callable(reset_law):
            reset_law()
        # per-agent copies of a law with memory of its own agents (module docstring)
        self._per_agent = bool(getattr(self.law, "memory_per_agent", False))
        self._blank = copy.deepcopy(self.law) if self._per_agent else None
        self._agent_laws: dict = {}

    # ------------------------------------------------------------------ public
    def compute(self, obs: Observation) -> np.ndarray:
        """Held commands (N, m), m/s^2, of the agents in ``obs`` after this step's updates."""
        obs.check_finite()
        n, m = obs.q.shape
        if self._m is None:
            self._m = m
            self._u = np.zeros((0, m))
            self._buf = Messages.empty(m)
            self._pending = Messages.empty(m)
        elif m != self._m:
            raise ValueError(f"space dimension changed from {self._m} to {m}; call reset()")
        t = float(obs.t)
        tol = 1e-6 * float(obs.dt)
        slots = self._register(obs, t, tol)
        due = self._clk.next_instant(slots) <= t + tol
        if due.any():
            self._send(obs, slots, due, t)
        self._deliver(t, tol)
        self._expire(t, tol)
        if due.any():
            self._update(obs, slots, due, t, tol)
        if self._agent_laws and len(self._agent_laws) > n:  # agents that left
            present = set(list(obs.ids))
            for gone in [a for a in self._agent_laws if a not in present]:
                del self._agent_laws[gone]
        return self._u[slots].copy()

    def buffer_view(self, receiver_id) -> dict:
        """Buffered messages of one receiver: ``{sender_id: (q, p, t_send)}`` (for tests)."""
        if self._buf is None or receiver_id not in self._slot_of:
            return {}
        sel = np.flatnonzero(self._buf.recv == self._slot_of[receiver_id])
        return {
            self._id_of[self._buf.send[k]]: (
                self._buf.q[k].copy(),
                self._buf.p[k].copy(),
                float(self._buf.t_send[k]),
            )
            for k in sel
        }

    # ------------------------------------------------------------------ steps
    def _register(self, obs: Observation, t: float, tol: float) -> np.ndarray:
        """Slots of ``obs.ids`` (new ids get a clock); agents that left are cleaned up."""
        ids = list(obs.ids)
        slots = np.empty(len(ids), np.int64)
        for r, key in enumerate(ids):
            s = self._slot_of.get(key)
            if s is None:
                s = len(self._id_of)
                self._slot_of[key] = s
                self._id_of.append(key)
            slots[r] = s
        if len(np.unique(slots)) != len(slots):
            raise ValueError("observation ids must be unique")
        cap = len(self._id_of)
        self._clk.grow(cap)
        if len(self._u) < cap:
            self._u = np.vstack([self._u, np.zeros((cap - len(self._u), self._m))])
        here = np.zeros(cap, bool)
        here[slots] = True
        gone = np.flatnonzero(self._clk.present & ~here)
        if len(gone):
            self._forget(gone)
        new = slots[~self._clk.present[slots]]
        if len(new):
            self._start_clocks(new, t, tol)
        return slots

    def _forget(self, gone: np.ndarray) -> None:
        """Agents that left: drop their buffers and messages in flight to them."""
        self._clk.present[gone] = False
        self._u[gone] = 0.0
        self._buf = self._buf.take(~np.isin(self._buf.recv, gone))
        self._pending = self._pending.take(~np.isin(self._pending.recv, gone))

    def _start_clocks(self, new: np.ndarray, t: float, tol: float) -> None:
        cfg = self.config
        clk = self._clk
        clk.present[new] = True
        self._u[new] = 0.0
        if cfg.mode == "synchronous":
            clk.base[new] = 0.0
            clk.period[new] = cfg.period_s
            clk.count[new] = math.ceil((t - tol) / cfg.period_s)
        else:
            period = cfg.period_s * (1.0 + cfg.period_jitter * self.rng.uniform(-1, 1, len(new)))
            clk.period[new] = period
            clk.base[new] = t + self.rng.random(len(new)) * period
            clk.count[new] = 0

    def _send(self, obs: Observation, slots: np.ndarray, due: np.ndarray, t: float) -> None:
        cfg = self.config
        senders = np.flatnonzero(due)
        n = obs.n
        if math.isinf(cfg.r_comm_m):
            src = np.repeat(senders, n)
            dst = np.tile(np.arange(n), len(senders))
        elif len(senders) * n <= _DENSE_SEND_MAX:
            # few senders (asynchronous clocks): a (B, N) distance table beats two KD-trees
            dq = obs.relative(obs.q[None, :, :] - obs.q[senders, None, :])
            a, dst = np.nonzero(np.einsum("bnk,bnk->bn", dq, dq) < cfg.r_comm_m**2)
            src = senders[a]
        else:
            pairs = cross_pairs(obs.q[senders], obs.q, cfg.r_comm_m, obs.period_s)
            src, dst = senders[pairs[:, 0]], pairs[:, 1]
        keep = src != dst
        src, dst = src[keep], dst[keep]
        order = np.lexsort((dst, src))
        src, dst = src[order], dst[order]
        n_msg = len(src)
        self.stats.sent += n_msg
        if n_msg == 0:
            return
        u_loss = self.rng.random(n_msg)
        u_delay = self.rng.random(n_msg)
        ok = u_loss >= cfg.loss_prob
        self.stats.lost += int(n_msg - np.count_nonzero(ok))
        delay = cfg.delay_min_s + (cfg.delay_max_s - cfg.delay_min_s) * u_delay
        useless = ok & (delay > cfg.expiry_s)
        self.stats.too_late += int(np.count_nonzero(useless))
        ok &= ~useless
        src, dst, delay = src[ok], dst[ok], delay[ok]
        if obs.length is not None and obs.width is not None:
            size = np.column_stack([obs.length[src], obs.width[src]])
        else:
            size = np.full((len(src), 2), np.nan)
        msgs = Messages(
            slots[dst], slots[src], np.full(len(src), t), t + delay, obs.q[src], obs.p[src], size
        )
        self._pending = Messages.concat(self._pending, msgs)

    def _deliver(self, t: float, tol: float) -> None:
        arrived = self._pending.t_arrive <= t + tol
        if not arrived.any():
            return
        new = self._pending.take(arrived)
        self._pending = self._pending.take(~arrived)
        allm = Messages.concat(self._buf, new)
        is_new = np.concatenate([np.zeros(len(self._buf), bool), np.ones(len(new), bool)])
        order = np.lexsort((allm.t_send, allm.send, allm.recv))
        allm, is_new = allm.take(order), is_new[order]
        last = np.ones(len(allm), bool)
        last[:-1] = (allm.recv[1:] != allm.recv[:-1]) | (allm.send[1:] != allm.send[:-1])
        self.stats.delivered += len(new)
        # A new copy older than what the buffer keeps (reordered by the random delays).
        self.stats.out_of_order += int(np.count_nonzero(is_new & ~last))
        self._buf = allm.take(last)

    def _expire(self, t: float, tol: float) -> None:
        if len(self._buf) == 0:
            return
        old = t - self._buf.t_send > self.config.expiry_s + tol
        if old.any():
            self.stats.expired += int(np.count_nonzero(old))
            self._buf = self._buf.take(~old)

    # ------------------------------------------------------------------ control
    def _update(
        self, obs: Observation, slots: np.ndarray, due: np.ndarray, t: float, tol: float
    ) -> None:
        clk = self._clk
        egos = np.flatnonzero(due)
        ego_slots = slots[egos]
        self.stats.agent_updates += len(egos)
        # advance the clocks past t
        s = ego_slots
        clk.count[s] = np.floor((t + tol - clk.base[s]) / clk.period[s]).astype(np.int64) + 1
        cap = len(self._id_of)
        block_of_slot = np.full(cap, -1, np.int64)
        block_of_slot[ego_slots] = np.arange(len(egos))
        entries = self._buf.take(block_of_slot[self._buf.recv] >= 0)
        if self._views_are_truth(obs, entries, len(egos), t, tol):
            u = np.asarray(self.law.compute(obs), dtype=float)
            self.stats.law_calls += 1
            self._u[ego_slots] = u
            return
        if self.config.extrapolate and len(entries):
            entries.q = entries.q + entries.p * (t - entries.t_send)[:, None]
        blocks = Views.build(obs, egos, entries, block_of_slot[entries.recv], self._id_of)
        axis = self._union_axis(obs)
        if self.batching == "union" and axis is None:
            raise ValueError(
                "batching='union' needs walls parallel to the block axis and m >= 2 on a ring"
            )
        if self.batching == "loop" or axis is None or len(egos) == 1:
            u = np.vstack([self._call(blocks.single(obs, b), self._id_of[ego_slots[b]])[0]
                           for b in range(len(egos))])
        else:
            union = blocks.union(obs, axis, self.block_gap_m)
            self.stats.union_rows += union.n
            u = self._call(union)[blocks.ego_rows]
        self._u[ego_slots] = u

    def _call(self, view: Observation, agent=None) -> np.ndarray:
        """The law's commands (rows of ``view``, m/s^2) on one agent's view (``agent``: its
        id: a law with memory of its own agents runs as that agent's copy) or on the
        union of views (``agent`` None: the shared law)."""
        self.stats.law_calls += 1
        law = self.law
        if self._per_agent and agent is not None:
            law = self._agent_laws.get(agent)
            if law is None:
                law = self._agent_laws[agent] = copy.deepcopy(self._blank)
        u = np.asarray(law.compute(view), dtype=float)
        if u.shape != view.q.shape:
            raise ValueError(f"law returned u of shape {u.shape}, expected {view.q.shape}")
        return u

    def _views_are_truth(
        self, obs: Observation, entries: Messages, n_egos: int, t: float, tol: float
    ) -> bool:
        """Every agent due and holding a fresh message from every other present agent."""
        n = obs.n
        if n_egos != n or len(entries) != n * (n - 1):
            return False
        return bool(np.all(np.abs(entries.t_send - t) <= tol))

    @staticmethod
    def _union_axis(obs: Observation) -> int | None:
        """Axis along which views can be laid side by side, or None."""
        axis = 0 if obs.period_s is None else 1
        if axis >= obs.m:
            return None
        if obs.road is not None:  # a road profile is read at true positions: no shifting
            return None
        if obs.walls is not None and len(obs.walls.points):
            if np.any(np.abs(obs.walls.normals[:, axis]) > 0):
                return None
        return axis
