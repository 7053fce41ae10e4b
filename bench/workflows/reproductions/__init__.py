"""Reproductions of the thesis' observer figures (Secs 4.3-4.4, 5.6.3), one module per group.

* `kubota_analysis` - Figs 4.6, 4.7: steady-state divergence analysis of Kubota's speed law.
* `speed_estimation` - Figs 4.8-4.12: speed estimators with measured-speed FOC.
* `closed_loop` - Figs 5.7-5.11: the LPV, JL and Kubota flux observers inside the FOC, with encoder
  speed (5.7, 5.8) and sensorless with Kubota's speed (5.9-5.11).
* `observer_errors` - the error table against the mock rig's ground truth (``python -m
  bench.workflows.reproductions.observer_errors``) and `observer_perf`, the per-tick cost benchmark.

Each figure registers with `bench.workflows.reproduce` and runs as ``bench reproduce NAME [--out DIR]``.
"""
