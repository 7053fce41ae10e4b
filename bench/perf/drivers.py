"""Benchmark: an emulated end-to-end run in real time (JSON; results in docs/RESULTS.md section 2).

    python3 -m bench.perf.drivers [--duration 10] [--rate 3000] [--emulator process|thread]
                                  [--interface tcp|virtual] [--lockstep]

Runs `bench run` logic (FOC, demo scenario, full MCAP logging) with the real drivers against the
emulators: by default `bench emulate` in a second process, CAN over loopback TCP, the front-end
on socket://, Modbus TCP - everything on 127.0.0.1. The trip limits on stale/lost frames and the
heartbeat are relaxed so that the run goes the whole way and the damage is counted instead:
frames stale (never arrived in time), lost, late, duplicated, CRC errors (from the status bits in
the log), deadline misses (overruns + skipped ticks), wake-up latency and per-tick compute time
(read -> write, which includes the wait for the emulator's sample).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from bench.hal import ST_MEAS_CRC, ST_MEAS_DUP, ST_MEAS_LATE, ST_MEAS_LOST, ST_MEAS_STALE
from mock_hw.emulators.links import free_ports
from mock_hw.emulators.testing import emulated_data, write_rig
from bench.daq import LogReader
from bench.runtime.session import RunOptions, run

ROOT = Path(__file__).resolve().parents[2]


def _rig(tmp: Path, rate: float, interface: str, autostart: str) -> Path:
    data = emulated_data(interface, limits={"stale_ticks": 10**6, "burst_count": 10**6},
                         can={"heartbeat_timeout": 10.0})  # fmt: skip
    data["rig"]["rate_hz"] = rate
    p_can, p_ser, p_mb = free_ports(3)
    if interface == "tcp":
        data["can"]["channel"] = f"127.0.0.1:{p_can}"
    data["serial"]["port"] = f"socket://127.0.0.1:{p_ser}"
    data["modbus"]["port"] = p_mb
    data["emulator"]["autostart"] = autostart
    return write_rig(tmp / "bench.toml", data)


def _cpu_times() -> list[int] | None:
    try:
        with open("/proc/stat") as f:
            return [int(x) for x in f.readline().split()[1:]]
    except (OSError, ValueError):
        return None


def run_benchmark(duration: float = 10.0, rate: float = 3000.0, emulator: str = "process", interface: str = "tcp",
                  realtime: bool = True) -> dict[str, Any]:  # fmt: skip

    if emulator == "process" and interface != "tcp":
        raise ValueError("an emulator in another process needs interface tcp")
    cpu0 = _cpu_times()
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        rig = _rig(tmp, rate, interface, "never" if emulator == "process" else "always")
        proc = None
        if emulator == "process":
            proc = subprocess.Popen([sys.executable, "-m", "bench", "emulate", "--rig", str(rig), "--duration",
                                     str(duration + 60)], cwd=ROOT, stdout=subprocess.PIPE, text=True)  # fmt: skip
            proc.stdout.readline()  # the emulator is listening
        try:
            log = tmp / "bench.mcap"
            summary, code = run(RunOptions(rig=str(rig), duration=duration, realtime=realtime, log=log,
                                           progress=False))  # fmt: skip
        finally:
            emu_stats = None
            if proc is not None:
                proc.send_signal(2)
                try:
                    out, _ = proc.communicate(timeout=30)
                    emu_stats = json.loads(out.strip().splitlines()[-1])["stats"]
                except (subprocess.TimeoutExpired, ValueError, IndexError, KeyError) as exc:
                    print(f"emulator: {exc!r}", file=sys.stderr)
                    proc.kill()
                    proc.communicate()
                    emu_stats = {"error": "emulator did not report its counters"}
        st = LogReader(log).read("/rig")["status"]
    cpu1 = _cpu_times()
    steal = None
    if cpu0 and cpu1 and len(cpu0) > 7:  # the hypervisor's share: CPU time this VM wanted but did not get
        d = [b - a for a, b in zip(cpu0, cpu1)]
        steal = d[7] / max(1, sum(d))
    ticks = summary["ticks"]
    frames = {name: int(np.count_nonzero(st & bit)) for name, bit in
              (("stale", ST_MEAS_STALE), ("lost", ST_MEAS_LOST), ("late", ST_MEAS_LATE),
               ("duplicated", ST_MEAS_DUP), ("crc_errors", ST_MEAS_CRC))}  # fmt: skip
    out: dict[str, Any] = {
        "benchmark": "emulated end-to-end", "rate_hz": rate, "duration_s": summary["duration"],
        "realtime": realtime, "emulator": emulator, "can_interface": interface,
        "ticks": ticks, "frames_ticks_with": frames,
        "frames_ok": ticks - frames["stale"],
        "deadline_misses": summary["deadline_misses"], "overruns": summary["overruns"],
        "skipped_ticks": summary["skipped_ticks"],
        "deadline_miss_fraction": summary["deadline_misses"] / max(1, ticks + summary["skipped_ticks"]),
        "realtime_factor": summary["realtime_factor"], "timing": summary["timing"],
        "trip_cause": summary["trip_cause"], "emulator_stats": emu_stats,
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "load_avg_1min": os.getloadavg()[0], "cpu_steal_fraction": steal},
    }  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=3000.0)
    ap.add_argument("--emulator", choices=("process", "thread"), default="process")
    ap.add_argument("--interface", choices=("tcp", "virtual"), default="tcp")
    ap.add_argument("--lockstep", action="store_true", help="lockstep instead of real time (throughput)")
    a = ap.parse_args()
    print(json.dumps(run_benchmark(a.duration, a.rate, a.emulator, a.interface, not a.lockstep), indent=2))


if __name__ == "__main__":
    main()
