"""Harnesses that try the bench from outside, as an attacker or a careless user would: the fault matrix (every way
a run can end, on real processes with real signals) and the input fuzzer (bad input of every kind). They drive the
runtime packages (bench, mock_hw) and are imported by none of them (an import-linter contract in pyproject.toml)."""
