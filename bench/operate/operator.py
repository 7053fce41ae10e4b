"""On-line operation of a running session: parameter changes, stop, e-stop and notes, and their replay.

The thesis' lab "allows selected parameters of the control system to be changed in real-time"
(App. A.7). Here three places take part:

* **clients** (Foxglove's Parameters panel and service calls, `bench set`, `bench stop|estop|mark`)
  talk to the live server in the log writer process (bench.daq.live), which checks every request
  against the session's `ParamSpace` (unknown, not tunable, wrong type, out of range: refused there,
  with a status to the client, and the run never sees it) and rate-limits them, per client;
* the **loop** takes the checked requests at a tick boundary (`Operator.service`, called before the
  tick reads the rig), applies each one whole between two ticks (a request of several changes: all of
  them or none), and reports each change as an event: tick, t, name, old value, new value, who, status;
* the **log** keeps those events on /params and /events, and `--replay-params LOG` re-applies a
  recorded session's changes and operator actions at the same ticks (`bench.operate.requests.ReplaySource`).

Operator actions: *stop* ramps the speed reference to zero at `STOP_RAMP`, zeroes the load command,
holds `STOP_HOLD`, then ends the run normally (exit 0); *e-stop* trips the supervisor, so the safe
command goes out in the same tick (exit 1); *mark* writes a note into the log. A live run's e-stop and
stop do not travel with the other requests: they are flags in shared memory that the loop reads every
tick, never rate-limited, never behind a parameter flood (bench.daq.live_control).

What a client may change, a request and the request sources are `bench.operate.requests` (shared with the live server);
this module is the loop's side: `Operator`, and the controllers prepared for a whole-controller switch.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from bench.controllers.schema import Param
from bench.errors import BadInput, allowed, clip, clip_repr
from bench.operate.requests import ACTIONS, CONTROLLER, MAX_NOTE, OFF, ParamSpace, Request
from bench import controllers as registry
from bench.controllers.base import Controller as Base

if TYPE_CHECKING:
    from bench.controllers.base import Controller

__all__ = ["Operator", "STOP_HOLD", "STOP_RAMP", "controller_param", "prepared_controllers"]

STOP_RAMP = 200.0  # [rad/s^2] (electrical) of the operator stop's speed ramp: 100 rad/s -> 0 in 0.5 s
STOP_HOLD = 0.2  # [s] at zero speed reference before the stop ends the run


def prepared_controllers(running: Controller, build: Callable[[str], Controller]) -> tuple[dict[str, Controller],
                                                                                           dict[str, str]]:  # fmt: skip
    """The plugins that can take over ``running`` while it runs, built before the loop with ``build(name)``: those
    whose class has a hand-over (`Controller.take_over_from`) and whose logged internals are the running one's
    (the log's controller topic is fixed at start). Returns (ready, {name: why not}) over the other plugins."""

    ready: dict[str, Controller] = {}
    why: dict[str, str] = {}
    for name, cls in registry.available().items():
        if name == running.name:
            continue
        if getattr(cls, "take_over_from", Base.take_over_from) is Base.take_over_from:
            why[name] = "it has no hand-over from a running controller"
            continue
        try:
            c = build(name)
        except BadInput as exc:
            why[name] = str(exc)
            continue
        if (c.topic, tuple(c.fields)) != (running.topic, tuple(running.fields)):
            why[name] = f"its logged internals differ from {running.name}'s (the log's {running.topic} is fixed at start)"
        else:
            ready[name] = c
    return ready, why


def controller_param(running: Controller, ready: Mapping[str, Controller]) -> dict[str, Param]:
    """The session parameter that switches the whole controller, if any plugin is ready to take over."""
    if not ready:
        return {}
    return {CONTROLLER: Param(running.name, "the controller plugin running (a whole-controller switch)",
                              choices=(running.name, *ready), tunable=True)}  # fmt: skip


def _shown(value: Any) -> Any:
    """A requested value as a report shows it: a number as it is, anything else as text cut short."""
    return value if isinstance(value, (bool, int, float)) or value is None else clip(value, 100)


class Operator:
    """The loop's side: applies requests between ticks, wraps the scenario's references.

    ``source`` has ``pending()`` (a cheap check) and ``take(k)``, and may have ``broken`` (why it can
    no longer be trusted: the run trips); ``report(event)`` receives one dict per request (applied or
    refused), in the order applied.
    """

    def __init__(self, ctrl: Controller, space: ParamSpace, source: Any, report: Callable[[dict], None],
                 request_trip: Callable[[str], None], busy: Callable[[], str | None] = lambda: None,
                 controllers: dict[str, Controller] | None = None) -> None:  # fmt: skip
        self.ctrl, self.space, self.source, self.report, self.request_trip = ctrl, space, source, report, request_trip
        self.busy = busy  # why the loop takes no part switches now (the supervisor's trip cause), or None
        # controllers prepared to take over the running one (`controller` switches, `prepared_controllers`); the
        # loop runs ``self.ctrl`` after each service
        self.controllers = dict(controllers or {})
        self.overrides: dict[str, float] = {}
        self.stopping_from: tuple[float, float] | None = None  # (t, speed reference) when the stop began
        self.stop_end: float = math.inf  # [s] when the stop ends the run
        self.applied = self.refused = 0
        self.ended_by: str | None = None
        self.epoch_ns = 0  # log_time of t = 0 (set by the loop)
        self._wake = getattr(source, "next_tick", math.inf)

    def due(self, k: int) -> bool:
        """Anything to do before tick ``k`` (called every tick: two compares when idle)."""
        return k >= self._wake or self.source.pending()

    def service(self, k: int, t: float) -> bool:
        """Apply what is due at tick ``k`` (loop time ``t``); True: the operator stop ends the run here."""
        if self.stopping_from is not None and t >= self.stop_end - 1e-12:
            self.ended_by = "operator stop"
            return True
        for req in self.source.take(k):
            self._apply(req, k, t)
        broken = getattr(self.source, "broken", None)  # a live run's request channel failed: a fault
        if broken:
            self.request_trip(broken)  # the e-stop or stop taken above, if any, came first
        nxt = getattr(self.source, "next_tick", math.inf)
        self._wake = min(nxt, k + 1) if self.stopping_from is not None else nxt
        return False

    def _apply(self, req: Request, k: int, t: float) -> None:
        base: dict[str, Any] = {"seq": req.seq, "tick": k, "t": t, "kind": req.kind, "who": req.who, "note": "",
                                "log_time": self.epoch_ns + int(t * 1e9)}  # as bench.runtime.loop  # fmt: skip
        if req.kind == "set":
            self._apply_set(req, base)
            return
        ev = {**base, "name": "", "old": None, "new": None, "status": "applied"}
        try:
            if req.kind == "estop":
                self.request_trip(f"operator e-stop ({req.who})" if req.who else "operator e-stop")
            elif req.kind == "stop":
                if self.stopping_from is None:
                    self.stopping_from = (t, math.nan)  # the reference it ramps from: the next tick's
            elif req.kind == "mark":
                ev["note"] = str(req.value)[:MAX_NOTE]
            else:
                raise BadInput("request", f"unknown kind {clip_repr(req.kind)}; allowed: set, {allowed(ACTIONS)}")
            self.applied += 1
        except BadInput as exc:  # refused in the loop
            ev["status"] = f"refused: {exc}"
            self.refused += 1
        self.report(ev)

    def _apply_set(self, req: Request, base: dict[str, Any]) -> None:
        """A parameter change or part switch, or several as one request: checked as a whole, then applied one
        after the other between two ticks; a refusal of any (e.g. a gain of a part that is not running) undoes
        the ones before it, so the request is applied whole or not at all. One report per change, each with
        the value in force before (applied) or still in force (refused)."""
        pairs = req.pairs()
        done: list[tuple[str, Any]] = []  # (name, old value) of the changes applied so far
        try:
            changes = self._checked(pairs)
            for name, value in changes:
                done.append((name, self._set(name, value)))
        except BadInput as exc:
            for name, old in reversed(done):  # the old values were in force a moment ago: they apply again
                try:
                    self._set(name, old)
                except BadInput:  # not for a gain or an override; a part switched back was running a moment ago
                    pass
            whole = f" (one request of {len(pairs)} changes: none applied)" if len(pairs) > 1 else ""
            self.refused += 1
            for name, value in pairs:
                self.report({**base, "name": clip(name, 100), "old": self._in_force(name), "new": _shown(value),
                             "status": f"refused: {exc}{whole}", "n": len(pairs)})  # fmt: skip
            return
        self.applied += 1
        for (name, old), (_, value) in zip(done, changes):
            self.report({**base, "name": name, "old": old, "new": value, "status": "applied", "n": len(changes)})

    def _checked(self, pairs: tuple[tuple[str, Any], ...]) -> list[tuple[str, Any]]:
        """The changes of one request as they will be applied, or `BadInput` naming the first one refused: each
        value checked, and a set of part switches checked as a whole (`check_switches` of the controller)."""
        names = [n for n, _ in pairs]
        twice = next((n for n in names if names.count(n) > 1), None)
        if twice is not None:
            raise BadInput(clip(twice), "given twice in one request")
        changes = [(n, self.space.check(n, v)) for n, v in pairs]
        parts = getattr(self.ctrl, "switchable", ())
        switches = [n for n, _ in changes if n == CONTROLLER or n in parts]
        if not switches:
            return changes
        if len(switches) < len(changes):
            other = next(n for n, _ in changes if n not in switches)
            raise BadInput(other, "one request either switches parts or changes parameters, not both (send them "
                           "one after the other)")  # fmt: skip
        why = "a stop is ramping down" if self.stopping_from is not None else self.busy()
        if why:
            raise BadInput(switches[0], f"no part switches now: {why}")
        if len(changes) > 1:
            if CONTROLLER in switches:
                raise BadInput(CONTROLLER, "a whole-controller switch goes alone, not with other parts")
            check = getattr(self.ctrl, "check_switches", None)
            if check is None:
                raise BadInput(switches[1], f"{self.ctrl.name} cannot switch several parts in one request")
            check(dict(changes))
        return changes

    def _set(self, name: str, value: Any) -> Any:
        """Apply one checked change; returns the old value (BadInput: refused, nothing changed)."""
        if name.endswith("_override"):
            old = self.overrides.get(name, OFF)
            if value == OFF:
                self.overrides.pop(name, None)
            else:
                self.overrides[name] = value
        else:
            old = self._switch_controller(value) if name == CONTROLLER else self.ctrl.set_param(name, value)
        self.space.values[name] = value
        return old

    def _in_force(self, name: Any) -> Any:
        """The value of parameter ``name`` in force now (None: not a parameter of this run)."""
        if not isinstance(name, str):
            return None
        if name.endswith("_override"):
            return self.overrides.get(name, OFF) if name in self.space.params else None
        if name == CONTROLLER:
            return self.ctrl.name
        return getattr(self.ctrl, "p", {}).get(name)

    def _switch_controller(self, name: str) -> str:
        """A whole-controller switch: the prepared ``name`` takes over the running one (`Controller.take_over_from`),
        which is kept for a switch back. Returns the old name; BadInput leaves the old one running."""
        old = self.ctrl.name
        if name == old:
            return old
        new = self.controllers.get(name)
        if new is None:
            raise BadInput(CONTROLLER, f"{name} is not prepared to take over (allowed: {allowed(self.controllers)})")
        new.take_over_from(self.ctrl)
        self.controllers[old] = self.ctrl
        del self.controllers[name]
        self.ctrl = new
        return old

    # ------------------------------------------------------------------ references
    def refs(self, speed_ref: Callable[[float], float], load: Callable[[float, float], float],
             i_mR_ref: Any) -> tuple[Any, Any, Any]:  # fmt: skip
        """The references in force: the scenario's own while no override or stop is active (so an idle
        operator costs the loop nothing but `due`), else wrapped."""
        ov = self.overrides
        stopping = self.stopping_from is not None
        return (self.speed_ref(speed_ref) if stopping or "omega_r_ref_override" in ov else speed_ref,
                self.load(load) if stopping or "m_l_ref_override" in ov else load,
                self.i_mR_ref(i_mR_ref) if "i_mr_ref_override" in ov else i_mR_ref)  # fmt: skip

    def speed_ref(self, scenario: Callable[[float], float]) -> Callable[[float], float]:
        ov = self.overrides

        def ref(t: float) -> float:
            w = ov.get("omega_r_ref_override")
            w = scenario(t) if w is None else w
            if self.stopping_from is None:
                return w
            t0, w0 = self.stopping_from
            if math.isnan(w0):  # the ramp starts from the reference in force when the stop came
                self.stopping_from = (t0, w)
                w0 = w
                self.stop_end = t0 + abs(w0) / STOP_RAMP + STOP_HOLD
            step = STOP_RAMP * (t - t0)
            return max(0.0, w0 - step) if w0 >= 0 else min(0.0, w0 + step)

        return ref

    def load(self, scenario: Callable[[float, float], float]) -> Callable[[float, float], float]:
        ov = self.overrides

        def m_L(t: float, omega_r: float) -> float:
            if self.stopping_from is not None:
                return 0.0
            m = ov.get("m_l_ref_override")
            return scenario(t, omega_r) if m is None else m

        return m_L

    def i_mR_ref(self, scenario: Any) -> Callable[[float], float]:
        ov = self.overrides

        def ref(t: float) -> float:
            i = ov.get("i_mr_ref_override")
            if i is not None:
                return i
            return scenario(t) if callable(scenario) else scenario

        return ref

    def summary(self) -> dict[str, Any]:
        return {"applied": self.applied, "refused_in_loop": self.refused, "ended_by": self.ended_by,
                "overrides": dict(self.overrides)}  # fmt: skip
