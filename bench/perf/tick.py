"""The lockstep tick's cost in yardsticks, and where it goes (issue 13: "profile first").

Rounds alternate a run without the log, one with full logging (MCAP through the writer process) and one
with the in-memory record every sweep case keeps (``memory``, `bench.daq.memory.MemoryLog`) (demo, FOC,
mock rig), each with the Python and the compiled engines: a "compiled" row runs the compiled plant
(``[mock] engine``, `mock_hw.compiled`) and the compiled FOC tick (controller parameter ``engine``,
`bench.controllers.foc_compiled`), a "python" row both references (`bench.perf.loop.run_benchmark`), so
machine noise hits all alike; the wall time per tick (with the log: put() and any wait for the writer included)
of the best round of each is reported in microseconds and in yardsticks (one plain-Python RK4 motor
step, ../shared/yardstick.py, measured before and after each round; the best of them; and, paired,
each round against the better of the yardsticks just before and after it). The default engine's
numbers are also at the top level, as before. A cProfile of one run without the log per engine
gives the share of the tick's own time (tottime) per part: the mock plant (mock_hw), the
controller (bench.controllers), the supervisor, the HAL, the loop itself.
"""

from __future__ import annotations

import cProfile
import pstats
from typing import Any

from bench.perf.live import yardstick_us
from bench.perf.loop import run_benchmark
from mock_hw.plant import resolve_engine

PARTS = (("mock plant", "/mock_hw/"), ("controller", "/bench/controllers/"),
         ("supervisor", "/bench/core/supervisor.py"), ("hal", "/bench/hal.py"), ("loop", "/bench/runtime/loop.py"),
         ("log (loop side)", "/bench/daq/"))  # fmt: skip


def _profile(duration: float, engine: str | None = None) -> dict[str, float]:
    pr = cProfile.Profile()
    pr.enable()
    run_benchmark("sim", duration, log=False, engine=engine)
    pr.disable()
    st = pstats.Stats(pr)
    share: dict[str, float] = {name: 0.0 for name, _ in PARTS}
    loop_total = 0.0
    for (file, _line, _func), (_cc, _nc, tt, _ct, _callers) in st.stats.items():  # type: ignore[attr-defined]
        for name, key in PARTS:
            if key in file:
                share[name] += tt
                loop_total += tt
                break
    return {k: v / loop_total for k, v in share.items()} if loop_total else share


def engines() -> tuple[str, ...]:
    """The engines to compare (plant and FOC): the Python references, and the compiled ones if numba imports."""
    return ("python", "compiled") if resolve_engine("auto") == "compiled" else ("python",)


def run(duration: float = 3.0, rounds: int = 3) -> dict[str, Any]:
    yards = [yardstick_us()]
    engs = engines()
    per: dict[str, dict[str, list[float]]] = {e: {"no_log": [], "log": [], "memory": []} for e in engs}
    log_arg = {"no_log": False, "log": True, "memory": "memory"}
    for e in engs:  # warm-up: compiled code loaded, first-run effects out of the rounds
        run_benchmark("sim", 0.1, log=False, engine=e)
    for _ in range(rounds):
        for e in engs:
            for kind in per[e]:
                res = run_benchmark("sim", duration, log=log_arg[kind], engine=e)
                # wall time per tick: with the log this includes put() and any wait for the writer process
                per[e][kind].append(1e6 * res["duration_s"] / res["ticks"] / res["sim_seconds_per_wall_second_loop"])
        yards.append(yardstick_us())  # once per round: the best yardstick goes with the best rounds
    ys = [y for y in yards if y]
    yard = min(ys) if ys else None
    out: dict[str, Any] = {"benchmark": "perf tick", "duration_s": duration, "rounds": rounds, "yardstick_us": yard,
                           "yardstick_us_rounds": yards, "default_engine": engs[-1]}  # fmt: skip
    by: dict[str, Any] = {}
    # paired: each round's tick against the better of the two yardsticks taken just before and after that round,
    # so a load that comes and goes during the run hits both sides of the ratio alike
    pair = [min(a, b) for a, b in zip(yards, yards[1:])] if len(ys) == len(yards) else None
    for e in engs:
        by[e] = {}
        for kind, xs in per[e].items():
            best = min(xs)
            paired = [x / y for x, y in zip(xs, pair)] if pair else None
            by[e][kind] = {"wall_us_per_tick_best": best, "rounds": xs, "yardsticks": best / yard if yard else None,
                           "yardsticks_paired": paired, "yardsticks_paired_best": min(paired) if paired else None,
                           "realtime_factor_at_3kHz": 1e6 / 3000 / best}  # fmt: skip
    out.update(by[engs[-1]])  # the default engine's numbers at the top level, as before
    out["by_engine"] = by
    out["share_of_tick_own_time_no_log"] = {e: _profile(min(duration, 1.0), e) for e in engs}
    return out
