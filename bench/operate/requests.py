"""Operator requests, the vocabulary that the live server (`bench.daq.live_control`, in the log writer process) and
the loop's operator (`bench.operate.operator.Operator`) share: what a client may see and change (`ParamSpace`, with the
session's own overrides, `session_params`), one checked request (`Request`, and how it travels between the two
processes), the actions, and the request sources that are not a live client: a replay (`ReplaySource`; read from
a log by `bench.daq.replay`) and a scenario's scheduled switches (`scheduled`), `merged` into one.

The overrides are bounded by the rig's own limits, `OVERRIDE_MARGIN` inside them (`session_params`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from bench.controllers.schema import Param
from bench.errors import BadInput, allowed, clip_repr
from bench.core.setpoints import MARGIN, Margins

if TYPE_CHECKING:
    from bench.controllers.base import Controller
    from bench.core.supervisor import Limits

__all__ = ["ACTIONS", "CONTROLLER", "MAX_NOTE", "OFF", "OVERRIDE_MARGIN", "ParamSpace", "ReplaySource", "Request",
           "merged", "scheduled", "session_params", "switch_names"]  # fmt: skip

ACTIONS = ("stop", "estop", "mark")
OFF = "off"  # the value that hands an override back to the scenario
MAX_NOTE = 1000  # characters of a mark's note
# the session parameter of a whole-controller switch (`bench.operate.operator.prepared_controllers`)
CONTROLLER = "controller"


def switch_names() -> tuple[str, ...]:
    """The parameters whose change is a switch (of a FOC part, or of the whole controller), for the log's readers."""
    from bench.controllers.foc import SWITCHABLE

    return (*SWITCHABLE, CONTROLLER)


OVERRIDE_MARGIN = MARGIN  # an override stays this fraction inside the rig's limit (bench.core.setpoints: the one rule)



def session_params(limits: Limits, torque_limit: float) -> dict[str, Param]:
    """The session's own tunables: overrides of the scenario's references ('off' hands back), each
    bounded as every set-point is (`bench.core.setpoints.Margins`, `OVERRIDE_MARGIN` inside the rig's limit): the
    speed inside the over-speed trip (``limits.omega_max``: a step's overshoot must not reach it), the load
    torque inside the load drive's clip (``torque_limit``, the rig file's), the flux current inside what
    controllers may request (``limits.I_max``: room is left for torque current)."""
    mg = Margins.of(limits, torque_limit)
    w, m, i = mg.omega, mg.torque, mg.i_mR
    return {
        "omega_r_ref_override": Param(0.0, "speed reference override, replaces the scenario's ('off': hand back)",
                                      "rad/s", ge=-w, le=w, tunable=True),
        "m_l_ref_override": Param(0.0, "load torque command override, replaces the scenario's ('off': hand back)",
                                  "N m", ge=-m, le=m, tunable=True),
        "i_mr_ref_override": Param(0.0, "flux reference i_mR override, replaces the scenario's ('off': hand back)",
                                   "A", gt=0.0, le=i, tunable=True),
    }  # fmt: skip


class ParamSpace:
    """Every parameter a client may see and the ones it may change: the controller's tunables
    (by their ``-p`` names) and the session's overrides. Plain data, so it also travels to the
    writer process (`describe` -> `from_description`)."""

    def __init__(self, params: Mapping[str, Param], values: Mapping[str, Any], fixed: Iterable[str] = (),
                 switchable: Iterable[str] = ()) -> None:  # fmt: skip
        self.params = dict(params)
        self.values = {k: values.get(k, OFF if k.endswith("_override") else p.default) for k, p in self.params.items()}
        self.fixed = sorted(fixed)  # the controller's other parameters: set at start only
        self.switchable = [k for k in switchable if k in self.params]  # the parts `bench switch` may change

    @classmethod
    def of(cls, ctrl: Controller, limits: Limits, torque_limit: float,
           switches: Mapping[str, Param] | None = None) -> ParamSpace:  # fmt: skip
        """The running controller's tunables and the overrides, bounded by the rig's ``limits`` and its
        load drive's ``torque_limit`` [N m]; ``switches``: the session's own switch (`controller_param`)."""
        sess = session_params(limits, torque_limit)
        tun = {k: p for k, p in ctrl.schema.items() if p.tunable}
        values = {k: ctrl.p[k] for k in tun} | {k: OFF for k in sess}
        switches = dict(switches or {})
        return cls(tun | sess | switches, values, (k for k in ctrl.schema if k not in tun),
                   (*getattr(ctrl, "switchable", ()), *switches))  # fmt: skip

    def check(self, name: Any, value: Any) -> Any:
        """The value as it will be applied, or `BadInput` naming the parameter and what is allowed."""
        if isinstance(name, str) and name in self.fixed:
            raise BadInput(name, f"cannot change while running (set it at start with -p); tunable: "
                           f"{allowed(sorted(self.params))}")  # fmt: skip
        if not isinstance(name, str) or name not in self.params:
            raise BadInput(f"param {clip_repr(str(name))}", f"unknown; allowed: {allowed(sorted(self.params))}")
        spec = self.params[name]
        if name.endswith("_override"):
            if value is None or (isinstance(value, str) and value.strip().lower() == OFF):
                return OFF
            if isinstance(value, str):  # a text field (Foxglove's panel shows the advertised 'off' as one): "2"
                try:
                    value = float(value)
                except ValueError:
                    raise BadInput(name, f"must be {spec.allowed()} or 'off', got {clip_repr(value)}") from None
        if spec.kind == "float" and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        return spec.check(name, value)

    def describe(self) -> dict[str, Any]:
        return {"fixed": self.fixed, "switchable": self.switchable, "params": [{"name": k, "value": self.values[k], "default": p.default, "doc": p.doc, "unit": p.unit,
                 "allowed": p.allowed() + (" or 'off'" if k.endswith("_override") else ""),
                 "bounds": [p.ge, p.gt, p.le, p.lt], "choices": p.choices}
                for k, p in self.params.items()]}  # fmt: skip

    @classmethod
    def from_description(cls, desc: Mapping[str, Any]) -> ParamSpace:
        params, values = {}, {}
        for d in desc["params"]:
            ge, gt, le, lt = d["bounds"]
            ch = tuple(d["choices"]) if d["choices"] is not None else None
            params[d["name"]] = Param(d["default"], d["doc"], d["unit"], ge=ge, gt=gt, le=le, lt=lt, choices=ch,
                                      tunable=True)  # fmt: skip
            values[d["name"]] = d["value"]
        return cls(params, values, desc["fixed"], desc.get("switchable", ()))


@dataclass(frozen=True)
class Request:
    """One checked request: ``kind`` "set" (name, value), or "set" of several ``items`` (name, value) that the
    loop applies whole between two ticks or refuses whole, or an action of ACTIONS (value: a mark's note)."""

    seq: int
    kind: str
    name: str = ""
    value: Any = None
    who: str = ""
    tick: int | None = None  # replay: the tick it was applied at in the recorded run
    items: tuple[tuple[str, Any], ...] = ()  # a "set" of several parameters (then name and value are unused)

    def pairs(self) -> tuple[tuple[str, Any], ...]:
        """The (name, value) changes of a "set": its items, or its one name and value."""
        return self.items or ((self.name, self.value),)

    def encode(self) -> bytes:
        return json.dumps([self.seq, self.kind, self.name, self.value, self.who, self.tick,
                           [list(p) for p in self.items]]).encode()  # fmt: skip

    @classmethod
    def decode(cls, data: bytes) -> Request:
        seq, kind, name, value, who, tick, *rest = json.loads(data)
        items = tuple((str(n), v) for n, v in rest[0]) if rest else ()
        return cls(int(seq), str(kind), str(name), value, str(who), tick, items)


class ReplaySource:
    """A recorded session's parameter changes and operator actions, due at the ticks they were applied."""

    def __init__(self, requests: Iterable[Request]) -> None:
        self._todo = sorted(requests, key=lambda r: (r.tick, r.seq))
        self._i = 0

    @property
    def next_tick(self) -> float:
        return self._todo[self._i].tick if self._i < len(self._todo) else math.inf  # type: ignore[return-value]

    def pending(self) -> bool:
        return False  # nothing arrives out of schedule

    def take(self, k: int) -> list[Request]:
        out = []
        while self._i < len(self._todo) and self._todo[self._i].tick <= k:  # type: ignore[operator]
            out.append(self._todo[self._i])
            self._i += 1
        return out


def scheduled(switches: Iterable[tuple[float, str, Any]], space: ParamSpace, T_s: float) -> ReplaySource | None:
    """A scenario's (or ``--switch``'s) scheduled switches as requests due at their ticks (who: "schedule"),
    each checked against the run's parameters first (`BadInput`: the run does not start)."""
    switches = list(switches)
    reqs = []
    for i, (t, name, value) in enumerate(switches):  # negative sequence numbers (a live client's count up from 0),
        space.check(name, value)  # increasing: two at one tick apply in the order given
        reqs.append(Request(i - len(switches), "set", name, value, "schedule", int(round(t / T_s))))
    return ReplaySource(reqs) if reqs else None


class _Merged:
    """Two request sources as one: a live inbox (or a replay) and a schedule."""

    def __init__(self, a: Any, b: Any) -> None:
        self.a, self.b = a, b

    @property
    def next_tick(self) -> float:
        return min(getattr(self.a, "next_tick", math.inf), self.b.next_tick)

    @property
    def broken(self) -> str | None:
        return getattr(self.a, "broken", None)

    def pending(self) -> bool:
        return self.a.pending()

    def take(self, k: int) -> list[Request]:
        return self.b.take(k) + self.a.take(k)


def merged(source: Any, schedule: ReplaySource | None) -> Any:
    """The request source of a run: ``source`` (a live inbox, a replay, None) and ``schedule`` together."""
    if schedule is None or source is None:
        return schedule if source is None else source
    return _Merged(source, schedule)
