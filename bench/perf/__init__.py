"""Every benchmark of the project, in one place; each prints JSON (`bench perf NAME`, docs/RESULTS.md).

| `bench perf ...` | module | what it measures |
|---|---|---|
| `loop` | `loop` | the real-time 3 kHz loop on the mock rig: deadline misses, latency, compute time |
| `sim` | `loop` | lockstep simulated seconds per wall second, with and without the log |
| `observers` | `observers` | per-call cost of every flux observer and speed estimator, and the FOC tick with each |
| `speed` | `speed` | per-call cost of the LPV speed controllers and the PI |
| `current` | `current` | per-tick cost of the current controllers |
| `narx` | `bench.workflows.narx.benchmark` | collect narx (two sets) + train narx |
| `writer` | `writer` | the MCAP logging path for several topic layouts |
| `drivers` | `drivers` | the real drivers against `bench emulate` in another process at 3 kHz |
| `plant` | `plant` | the mock rig's read + write per tick |
| `synthesis` | `synthesis` | wall time of the flux-observer (5.6.2) and current-controller (6.2.2) syntheses |
| `robust` | `robust` | the robust LPV synthesis of Ch. 7 and its checks |
| `live` | `live` | real-time runs with and without the live stream and a subscribed client |
| `tick` | `tick` | the lockstep tick in yardsticks without and with the log, and its profile by part |
| `operator` | `operator` | lockstep tick cost without, with an idle and with a busy on-line operator |
| `switch` | `switch` | real-time runs with 20 part switches and without, side by side: deadline misses, compute at the switches |
| `sweep` | `sweep` | `bench sweep` throughput: serial in-process vs Dask with 1 and 2 workers (overhead, efficiency) |
| `batch` | `batch` | the batch engine: motor-ticks/s vs batch size, the scalar engine side by side; `--atlas`: the atlas' cases it covers |

Per-tick costs are compared with `../shared/yardstick.py` (one plain-Python RK4 step of the motor)
measured in the same run, since the machine is shared and noisy.
"""
