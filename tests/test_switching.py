"""Parts of the FOC switched while the motor runs: bumpless hand-over, strict refusals, replay (lockstep, mock rig)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from bench.errors import BadInput
from bench.runtime.session import RunOptions, run

U_RATED = 380.0 * (2.0 / 3.0) ** 0.5  # [V] phase amplitude at the rated 380 V (App. A)
M_RATED = 10.0  # [N m] (App. A)
T1, T2, DURATION = 1.5, 2.3, 3.1  # switch there and back at the `hold` scenario's steady point (100 rad/s, 5 N m)


def switched(part: str, to: str, back: str, **params: object) -> dict:
    opts = RunOptions(scenario="hold", duration=DURATION, params=dict(params), log_enabled=False, progress=False,
                      switches=((T1, part, to), (T2, part, back)))  # fmt: skip
    summary, code = run(opts)
    assert code == 0 and summary["trip_cause"] is None
    sw = summary["switches"]
    assert [(s["part"], s["to"]) for s in sw] == [(part, to), (part, back)]
    return summary


PAIRS = [("current_controller", "lpv", "pi", {}), ("observer", "lpv", "current_model", {}),
         ("observer", "jl", "current_model", {}), ("observer", "kubota", "voltage_model", {}),
         ("speed_source", "estimate", "encoder", {"speed_estimator": "rotor_equation"})]  # fmt: skip


@pytest.mark.parametrize("part,to,back,params", PAIRS, ids=[f"{p}-{a}-{b}" for p, a, b, _ in PAIRS])
def test_a_switch_in_steady_state_is_bumpless(part: str, to: str, back: str, params: dict) -> None:
    """Voltage-reference jump <= 2 % of the rated voltage and true torque transient <= 5 % of rated torque, both ways
    (the return from the sensorless speed: only the jump, see test_the_sensorless_return_corrects_the_speed)."""
    for s in switched(part, to, back, **params)["switches"]:
        assert s["u_jump"] <= 0.02 * U_RATED, s
        if not (part == "speed_source" and s["to"] == "encoder"):
            assert s["torque_transient"] <= 0.05 * M_RATED, s


def test_the_sensorless_return_corrects_the_speed() -> None:
    """Back on the encoder, the speed PI removes the estimate's error: a torque transient, no jump in the command."""
    s = switched("speed_source", "estimate", "encoder", speed_estimator="rotor_equation")["switches"][1]
    assert s["u_jump"] <= 0.02 * U_RATED
    assert s["torque_transient"] < 0.1 * M_RATED


def test_the_lpv_speed_law_takes_over_within_its_own_steady_noise() -> None:
    """The LPV speed law (6.4.3) has a large direct feed-through of the encoder speed: its own steady tick-to-tick
    command steps are ~30 V at this point, so a switch to it is measured against them (their largest over 0.2 s,
    settled); the return to the PI starts at the LPV law's last output: no jump in the command, and the torque
    moves no more than it did under the LPV law just before. The torque under the LPV law moves by 3-4 N m by
    itself: the switch's largest excursion (over 50 ms) is held against the law's own over its whole settled
    stretch (1 s, from `SWITCH_LATER` after the switch to the switch back). Against the metric's 0.2 s, the largest
    of four such windows, a perfect hand-over would fail one time in five."""
    from bench.runtime.metrics import SWITCH_LATER

    t2 = T1 + SWITCH_LATER + 1.0
    summary, code = run(RunOptions(scenario="hold", duration=t2 + 0.8, log_enabled=False, progress=False,
                                   switches=((T1, "speed_controller", "lpv"), (t2, "speed_controller", "pi"))))
    assert code == 0 and summary["trip_cause"] is None
    to_lpv, to_pi = summary["switches"]
    assert to_lpv["u_jump"] <= to_lpv["u_step_later"] and to_lpv["u_step_later"] > 0.02 * U_RATED
    t, m_e = summary["record"].read("/rig")["t"], summary["record"].read("/truth")["m_e"]
    own = m_e[(t >= T1 + SWITCH_LATER) & (t < t2)]
    assert to_lpv["torque_transient"] <= float(np.max(np.abs(own - own.mean())))
    assert to_pi["u_jump"] <= 0.02 * U_RATED and to_pi["torque_transient"] <= to_pi["torque_before"]


@pytest.mark.parametrize("part,to,back", [("observer", "jl", "current_model"), ("current_controller", "lpv", "pi")])
def test_without_the_hand_over_the_jump_is_clearly_larger(part: str, to: str, back: str) -> None:
    warm = switched(part, to, back)["switches"][0]
    opts = RunOptions(scenario="hold", duration=DURATION, params={"handover": "cold"}, log_enabled=False,
                      progress=False, switches=((T1, part, to),))  # fmt: skip
    summary, _ = run(opts)
    cold = summary["switches"][0]
    assert cold["u_jump"] > 5 * warm["u_jump"] and cold["u_jump"] > 0.05 * U_RATED, (warm, cold)


def test_a_whole_controller_switch_to_the_relay_and_back() -> None:
    """relay_tune (a FOC with a relay in place of the speed PI) takes over the running FOC and hands back; the FOC
    takes over bumpless (the relay's last torque, the same field frame). A plugin without a hand-over is refused."""
    summary, code = run(RunOptions(scenario="fig5.7", duration=2.7, log_enabled=False, progress=False,
                                   switches=((1.2, "controller", "relay_tune"), (1.9, "controller", "foc"))))  # fmt: skip
    assert code == 0
    ev = summary["record"].events()
    assert [(e["name"], e["old"], e["new"], e["status"]) for e in ev] == [
        ("controller", "foc", "relay_tune", "applied"), ("controller", "relay_tune", "foc", "applied")]  # fmt: skip
    to_relay, back = summary["switches"]
    assert to_relay["u_step_later"] > 5 * to_relay["u_step_before"]  # the relay bangs: it did take over
    assert back["u_jump"] <= 0.02 * U_RATED and back["u_step_later"] <= 0.02 * U_RATED


def test_a_replay_reproduces_a_run_with_switches_and_the_compiled_engine_hands_over_exactly(tmp_path) -> None:
    """The switches are on /params; --replay-params applies them at the same ticks: every logged field equal. The
    compiled engine runs to the first switch and hands its state to the Python engine exactly: the same log."""
    from bench.daq import LogReader

    sw = ((T1, "observer", "lpv"), (T1 + 0.2, "current_controller", "lpv"), (T2, "speed_controller", "lpv"))
    logs = {}
    for name, extra in (("python", {}), ("compiled", {"engine": "compiled"})):
        logs[name] = tmp_path / f"{name}.mcap"
        run(RunOptions(scenario="hold", duration=DURATION, params=extra, switches=sw, log=logs[name], progress=False))
    replay = tmp_path / "replay.mcap"
    run(RunOptions(scenario="hold", duration=DURATION, replay_params=logs["python"], log=replay, progress=False))
    ref = LogReader(logs["python"])
    for other in (logs["compiled"], replay):
        r = LogReader(other)
        assert [(e["tick"], e["name"], e["new_text"]) for e in r.events()] == \
               [(e["tick"], e["name"], e["new_text"]) for e in ref.events()]  # fmt: skip
        for topic in ("/rig", "/ctrl", "/truth"):
            a, b = ref.read(topic), r.read(topic)
            for f in a:
                if f not in ("compute_us", "latency_us", "overrun", "log_time"):
                    assert np.array_equal(a[f], b[f], equal_nan=True), (other.name, topic, f)


def test_switches_at_one_tick_apply_in_the_order_given() -> None:
    summary, code = run(RunOptions(scenario="fig5.7", duration=1.5, log_enabled=False, progress=False,
                                   switches=((1.0, "observer", "lpv"), (1.0, "observer", "jl"))))  # fmt: skip
    assert code == 0
    assert [(e["tick"], e["old"], e["new"]) for e in summary["record"].events()] == [
        (3000, "current_model", "lpv"), (3000, "lpv", "jl")]  # fmt: skip


def test_switches_that_cannot_be_had_are_refused_and_the_old_part_runs_on() -> None:
    from bench.core.config import load
    from bench.runtime.compose import build_rig, make_controller

    cfg = load("mock")
    ctrl = make_controller(cfg, build_rig(cfg, 0), "foc", {})
    with pytest.raises(BadInput, match="no speed estimator runs"):
        ctrl.set_param("speed_source", "estimate")
    assert ctrl.p["speed_source"] == "encoder" and not ctrl._sensorless
    bad = make_controller(cfg, build_rig(cfg, 0), "foc", {"lpv_speed_artifact": "/nonexistent/speed"})
    assert "speed_controller=lpv" in bad.prepare_switching()
    with pytest.raises(BadInput, match="lpv cannot be had"):
        bad.set_param("speed_controller", "lpv")
    assert bad.p["speed_controller"] == "pi" and type(bad.speed).__name__ == "SpeedPI"
    shared = make_controller(cfg, build_rig(cfg, 0), "foc", {"observer": "kubota", "speed_estimator": "kubota"})
    with pytest.raises(BadInput, match="cannot switch"):
        shared.set_param("observer", "current_model")


def test_a_switch_during_a_stop_or_after_a_trip_is_refused() -> None:
    from bench.core.config import load
    from bench.operate.operator import Operator
    from bench.operate.requests import ParamSpace, ReplaySource, Request
    from bench.runtime.compose import build_rig, make_controller

    cfg = load("mock")
    ctrl = make_controller(cfg, build_rig(cfg, 0), "foc", {})
    space = ParamSpace.of(ctrl, cfg.limits, 10.0)
    events: list[dict] = []
    cause: list[str | None] = [None]
    src = ReplaySource([Request(0, "stop", tick=1), Request(1, "set", "speed_controller", "lpv", "t", 2),
                        Request(2, "set", "current_controller", "lpv", "t", 3)])  # fmt: skip
    op = Operator(ctrl, space, src, events.append, lambda why: None, busy=lambda: cause[0])
    op.service(1, 1 / 3000)
    op.service(2, 2 / 3000)
    assert events[-1]["status"].startswith("refused") and "stop is ramping" in events[-1]["status"]
    op.stopping_from = None
    cause[0] = "over-current"
    op.service(3, 3 / 3000)
    assert events[-1]["status"].startswith("refused") and "over-current" in events[-1]["status"]
    assert ctrl.p["speed_controller"] == "pi" and ctrl.p["current_controller"] == "pi"


def test_bad_switch_options_are_one_line_errors(tmp_path) -> None:
    for args, word in ((["--switch", "1:speed_controller=fast"], "speed_controller"),
                       (["--switch", "99:observer=jl"], "--switch"), (["--switch", "nonsense"], "--switch"),
                       (["--switch", "1:speed_Kp=3"], ""), (["--switch", "1:controller=excitation"], "no hand-over"),
                       (["-p", "lpv_speed_artifact=/nonexistent/x", "--switch", "1:speed_controller=lpv"], "cannot be had")):  # fmt: skip
        p = subprocess.run([sys.executable, "-m", "bench", "run", "--scenario", "hold", "--duration", "2",
                            "--no-progress", "--out", str(tmp_path), *args], capture_output=True, text=True)  # fmt: skip
        lines = p.stderr.strip().splitlines()
        if args[1] == "1:speed_Kp=3":  # a tunable gain may be scheduled too: the run goes
            assert p.returncode == 0, p.stderr
            continue
        assert p.returncode == 2 and len(lines) == 1 and word in lines[0] and "Traceback" not in p.stderr, (args, p.stderr)


@pytest.mark.realtime
def test_a_real_time_switch_through_the_live_service_and_the_parameters_panel(tmp_path) -> None:
    """`bench switch` (the /switch service) and a plain parameter set (what Foxglove's Parameters panel sends) switch
    parts of a real-time run; a refused switch names why and the run goes on; the replay reproduces the run.
    At 10 rad/s (fig5.7), not the rated point, and after its speed step: a stall there under the LPV laws is tested
    in lockstep (tests/test_ride_through.py), which is not this test's subject; the same switches at the rated point
    are tested in lockstep above."""
    import json
    import time
    from pathlib import Path

    from bench.daq import LogReader

    root = Path(__file__).resolve().parents[1]
    log = tmp_path / "live.mcap"
    p = subprocess.Popen([sys.executable, "-m", "bench", "run", "--no-progress", "--realtime", "--duration", "30",
                          "--scenario", "fig5.7", "--log", str(log), "--live", "--live-port", "0"], cwd=root,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip

    def bench(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "bench", *args, "--port", port], cwd=root, capture_output=True,
                              text=True, timeout=30)  # fmt: skip

    try:
        line = p.stderr.readline()
        assert line.startswith("bench: live: ws://127.0.0.1:"), line
        port = line.split("ws://127.0.0.1:")[1].split()[0]
        # the switches come after fig5.7's speed step at 0.4 s: a loop stall of 4-12 ms just after it, under the LPV
        # speed and current laws, runs the current to within 3 % of the trip (tests/test_ride_through.py; it tripped
        # this test once in CI), which is the laws' subject, not this test's
        for _ in range(100):
            mark = bench("mark", "after the speed step")
            assert mark.returncode == 0, mark.stderr
            if float(mark.stdout.split("(t = ")[1].split(" s)")[0]) > 0.6:
                break
            time.sleep(0.05)
        else:
            raise AssertionError(f"the run did not reach 0.6 s: {mark.stdout}")
        ok = bench("switch", "speed_controller=lpv", "observer=lpv")
        assert ok.returncode == 0 and "speed_controller -> lpv at tick" in ok.stdout and "observer -> lpv" in ok.stdout, \
            ok.stderr  # fmt: skip
        bad = bench("switch", "speed_source=estimate")
        assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "no speed estimator runs" in bad.stderr, bad.stderr
        unknown = bench("switch", "flux_Km=3")
        assert unknown.returncode == 2 and "part must be one of" in unknown.stderr, unknown.stderr
        panel = bench("set", "current_controller=lpv")
        assert panel.returncode == 0 and "current_controller: pi -> lpv" in panel.stdout, panel.stderr
        stop = bench("stop")
        if stop.returncode != 0:  # the run ended before the stop: say how (its stderr: the trip's cause)
            out, err = p.communicate(timeout=60)
            summary = tmp_path / "live.summary.json"
            why = json.loads(summary.read_text()).get("trip_cause") if summary.exists() else None
            raise AssertionError(f"bench stop: {stop.stderr.strip()}; the run ended first (exit {p.returncode}, "
                                 f"trip cause {why!r}): {err[-2000:]}")
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err
    summary = json.loads((tmp_path / "live.summary.json").read_text())
    assert [s["to"] for s in summary["switches"]] == ["lpv", "lpv", "lpv"][: len(summary["switches"])]
    evs = [e for e in LogReader(log).events() if e.get("name") in ("speed_controller", "observer", "speed_source",
                                                                   "current_controller")]  # fmt: skip
    assert [(e["name"], e["status"].split(":")[0]) for e in evs] == [
        ("speed_controller", "applied"), ("observer", "applied"), ("speed_source", "refused"),
        ("current_controller", "applied")]  # fmt: skip
    # offline replay (lockstep): the same switches at the same ticks (field for field only where the real-time run
    # skipped no tick: a skipped tick is integrated over by the mock plant; lockstep equality is tested above)
    replay = tmp_path / "replay.mcap"
    run(RunOptions(scenario="fig5.7", duration=30, replay_params=log, log=replay, progress=False))
    again = [e for e in LogReader(replay).events() if e["status"] == "applied" and e.get("name")]
    assert [(e["tick"], e["name"], e["new_text"]) for e in again] == \
        [(e["tick"], e["name"], e["new_text"]) for e in evs if e["status"] == "applied"]  # fmt: skip


@pytest.mark.realtime
def test_the_terminal_panel_shows_the_last_switch(tmp_path, run_in_pty) -> None:
    """A real-time run with stderr a terminal (a pty): after a scheduled switch the panel line names it."""
    import re

    code, text = run_in_pty([sys.executable, "-m", "bench", "run", "--realtime", "--duration", "2.5", "--scenario",
                             "fig5.7", "--switch", "1:observer=lpv", "--switch", "1.5:current_controller=lpv", "--log",
                             str(tmp_path / "tty.mcap")], columns=260)  # fmt: skip
    assert code == 0, text[-2000:]
    rows = re.findall(r"t +([\d.]+) s .*?(?:observer|current_controller) \u2192 (\w+) at ([\d.]+) s \((\d+) switch", text)
    assert rows, text[-2000:]
    assert all(float(t) >= 1.0 for t, *_ in rows) and rows[-1][1:] == ("lpv", "1.50", "2"), rows[-3:]


def test_switches_with_a_replay_are_refused_not_dropped(tmp_path) -> None:
    """--switch with --replay-params: the replay applies the recorded run's switches, so extra ones are refused in one
    line (they used to be dropped without a word)."""
    from bench.errors import BadInput
    from bench.runtime.session import RunOptions, prepare

    with pytest.raises(BadInput) as exc:
        prepare(RunOptions(scenario="hold", replay_params=tmp_path / "run.mcap", switches=((1.0, "observer", "jl"),)))
    assert exc.value.field == "--switch" and "--replay-params" in exc.value.problem
