"""Errors for bad user input: each carries the field it is about and what is allowed.

The CLI turns a `BadInput` into a single line on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations


class BadInput(ValueError):
    """Invalid user input (rig file, scenario, controller, parameter)."""

    def __init__(self, field: str, problem: str) -> None:
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}")


def allowed(values: object) -> str:
    """Format a list of allowed values for an error message."""
    return ", ".join(str(v) for v in values)
