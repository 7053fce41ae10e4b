"""Parameter sweeps and Monte-Carlo studies: many ordinary lockstep sessions on Dask (`bench sweep`).

* `spec`: the sweep file (TOML): base rig, controller, fixed parameters and plant, the design
  (grid, random or Latin hypercube), seeds; validated into a `SweepSpec`;
* `plant`: the mismatch keys (R_r factor, sensor noise, dead time, ...) and how they change a rig's
  ``[mock]`` table;
* `cases`: the spec expanded into `Case` records (each keyed by a hash of its inputs), and
  `run_case`, one session on a mock rig, returning one results row;
* `table`: ``results.parquet`` (pyarrow), read and written atomically;
* `engine`: the cases on a Dask cluster (an embedded local one, or a scheduler's address), resume,
  retries, progress;
* `tasks`: computation sweeps (``[sweep] task``): Fig. 5.5's grid, the pipeline's NARX candidates;
* `report`: plots and a markdown summary of a results table.

docs/sweeps.md describes the file format and the measured throughput.
"""
