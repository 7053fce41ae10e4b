"""What every layer of the bench shares: rig files and the nameplate, scenarios and set-point margins, the
supervisor's checks, the encoder and inverter-error models, the run metrics, the compiled kernels' machinery
(named state slots, CPython's arithmetic for numba, the JIT cache), output files, plots and progress.
Imports nothing of the layers above (docs/architecture.md)."""
