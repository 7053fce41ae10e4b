"""Reproductions of the thesis' observer figures (Secs 4.3-4.4, 5.6.3), one module per group.

* `kubota_analysis` - Figs 4.6, 4.7: steady-state divergence analysis of Kubota's speed law.
* `speed_estimation` - Figs 4.8-4.12: speed estimators with measured-speed FOC.
* `sensorless` - Figs 5.9-5.11: sensorless FOC with each flux observer and Kubota's speed.
* `observer_errors` - the error table against the mock rig's ground truth (``python -m
  bench.reproductions.observer_errors``) and `observer_perf`, the per-tick cost benchmark.

Each figure registers with `bench.reproduce` and runs as ``bench reproduce NAME [--out DIR]``.
"""
