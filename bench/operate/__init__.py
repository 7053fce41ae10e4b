"""Operating a running session: the operator's requests, their handling and replay, the command-line live client
and the Foxglove layout (docs/architecture.md)."""
