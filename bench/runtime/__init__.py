"""Running one session: the composition root that builds a rig, the timed loop, the real-time host, the one
shutdown path and the run summary (docs/architecture.md)."""
