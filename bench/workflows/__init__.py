"""The workflows built on sessions: commissioning, sweeps, thesis reproductions, synthesis, NARX collection and
training, the pipeline, relay tuning and rig-file writing (docs/architecture.md)."""
