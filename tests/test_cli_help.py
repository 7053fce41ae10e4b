"""Every command's help reads as meant: no ``None`` where click would describe an open range."""

from __future__ import annotations

import click

from bench.cli import cli


def _helps(cmd: click.Command, path: list[str]):
    yield path, cmd.get_help(click.Context(cmd, info_name=" ".join(path)))
    if isinstance(cmd, click.Group):
        for name, sub in cmd.commands.items():
            yield from _helps(sub, [*path, name])


def test_no_help_text_says_none():
    helps = dict((" ".join(p), h) for p, h in _helps(cli, ["bench"]))
    assert len(helps) > 30 and "bench run" in helps
    bad = {p: [ln for ln in h.splitlines() if "None" in ln] for p, h in helps.items() if "None" in h}
    assert not bad, bad
    assert "--duration FLOAT " in helps["bench run"]  # unbounded: a plain FLOAT
    assert "0<x<=100" in helps["bench tune speed"]  # bounded ranges keep click's description
