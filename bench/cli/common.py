"""What every `bench` command shares: the `cli` group, the option types that refuse bad input in one line, the
parsers of NAME=VALUE options, the pacing and live options, and how a command reports its end."""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from bench.errors import BadInput, clip, clip_repr
from bench.core.outputs import check_name, written_note


EXIT_BAD_INPUT = 2


class FiniteRange(click.FloatRange):
    """click.FloatRange that also refuses nan and inf (they pass every comparison click makes).

    Without bounds its help says FLOAT (click's would be ``FLOAT RANGE [x<=None]``)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if self.min is None and self.max is None:
            self.name = "float"

    def _describe_range(self) -> str:
        return "" if self.min is None and self.max is None else super()._describe_range()

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        import math

        v = super().convert(value, param, ctx)
        if not math.isfinite(v):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return v


FINITE = FiniteRange()  # any finite float


class OutFile(click.Path):
    """An output file path (``click.Path(dir_okay=False)``) that names a file the file system can make:
    not empty (click turns '' into '.'), no name over NAME_MAX (bench.core.outputs.check_name)."""

    def __init__(self) -> None:
        super().__init__(dir_okay=False, path_type=Path)

    def convert(self, value: Any, param: Any, ctx: Any) -> Any:
        if isinstance(value, str) and not value.strip():
            self.fail("needs a file name, got ''", param, ctx)
        path = super().convert(value, param, ctx)
        check_name("/".join(param.opts) if param is not None else "path", path)
        return path


def _parse_params(items: tuple[str, ...], option: str = "--param") -> dict[str, Any]:
    """``-p NAME=VALUE`` items (of ``option``) -> {name: value}; VALUE is read as a TOML value (number, true,
    "text") or, if it is not one, taken as a string. One parameter per item."""
    out: dict[str, Any] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise BadInput(option, f"expected NAME=VALUE, got {clip_repr(item)}")
        if any(c in item for c in "\n\r\0"):
            raise BadInput(option, f"one NAME=VALUE per item, without line breaks, got {clip_repr(item)}")
        if name.strip() in out:
            raise BadInput(f"{option} {clip(name.strip())}", "given twice")
        try:
            out[name.strip()] = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError:
            out[name.strip()] = value
        except ValueError:  # an integer of more than 4300 digits (Python's int-conversion limit)
            raise BadInput(f"{option} {clip(name.strip())}",
                           f"a number of {len(value.strip())} digits is not a parameter value") from None
    return out


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="imbench")
def cli() -> None:
    """imbench: induction-motor test bench (thesis: Trangbaek 2001)."""


def _pacing_options(f: Callable) -> Callable:
    """--realtime/--lockstep and --allow-soft-realtime, shared by every command that runs a session."""
    f = click.option("--allow-soft-realtime", is_flag=True,
                     help="run a real rig even where SCHED_FIFO cannot be applied (recorded in the summary)")(f)  # fmt: skip
    return click.option("--realtime/--lockstep", "realtime", default=None,
                        help="pace the loop by the wall clock, or run simulated time as fast as possible "
                             "[default: real time on a rig with real devices (refuses --lockstep), else lockstep]")(f)  # fmt: skip


def _live_options(f: Callable) -> Callable:
    """--live, --live-port, --live-host, --live-rate: the same on every command that runs a session."""
    f = click.option("--live-rate", type=FINITE, default=100.0, show_default=True,
                     help="/rig, /ctrl, /truth rate on the live stream [Hz]")(f)  # fmt: skip
    f = click.option("--live-host", default="127.0.0.1", show_default=True,
                     help="live server address; anything but loopback opens it to the network (no authentication)")(f)  # fmt: skip
    f = click.option("--live-port", type=int, default=8765, show_default=True,
                     help="live server port (0: any free one)")(f)  # fmt: skip
    return click.option("--live", is_flag=True, help="serve the run live to Foxglove (WebSocket, from the log writer)")(f)


def _live(live: bool, live_port: int, live_host: str, live_rate: float) -> dict[str, Any]:
    """RunOptions fields for the live stream, with the warning a network-facing server deserves."""
    if live and live_host not in ("127.0.0.1", "localhost", "::1"):
        from bench.runtime.session import check_live_address

        if 0 <= live_port <= 65535:  # an address this machine lacks: the one-line error, not the warning
            check_live_address(live_host, live_port)
        click.echo(f"bench: warning: the live server on {live_host} has no authentication: anyone who can reach it "
                   "sees the rig's data, changes tunable parameters and can stop the run", err=True)  # fmt: skip
    return {"live_port": live_port if live else None, "live_host": live_host, "live_rate": live_rate}


def _report_end(result: dict[str, Any], code: int, keys: tuple[str, ...] | None = None) -> None:
    """The run's numbers on stdout (JSON), and a line on stderr if it did not end normally.

    The summary file is already written; one that could not be (a full disk) is printed here in full
    on stderr, and the last line says which files were and were not written. A closed terminal
    (SIGHUP) must not turn this into an error.
    """
    try:
        if keys is not None:
            click.echo(json.dumps({k: result.get(k) for k in keys}, indent=2, default=str))
        if "summary" in result and not result["summary"]:  # its file could not be written: it is not lost
            full = json.dumps({k: v for k, v in result.items() if k != "record"}, indent=2, default=str)
            click.echo(f"bench: the summary in full (its file could not be written):\n{full}", err=True)
        cause = result.get("trip_cause")
        if cause:
            t = result.get("trip_time")
            when = f" at t = {t:.4f} s" if isinstance(t, float) else ""
            word = "INTERRUPTED" if code >= 128 else "TRIPPED"
            click.echo(f"bench: {word}{when}: {cause} (rig safe; {written_note(result)})", err=True)
        for warning in result.get("warnings") or ():
            click.echo(f"bench: warning: {warning}", err=True)
    except OSError:  # stdout/stderr gone
        pass


def _parse_scenario_args(items: tuple[str, ...]) -> dict[str, float]:
    """``NAME=VALUE`` items of --scenario-arg (the names checked against the scenario when the run starts)."""
    out = {}
    for item in items:
        name, eq, value = item.partition("=")
        try:
            v = float(value)
        except ValueError:
            v = math.nan
        if not eq or not name.strip() or not math.isfinite(v):
            raise BadInput("--scenario-arg", f"must be NAME=NUMBER (e.g. speed=80), got {clip_repr(item)}")
        out[name.strip()] = v
    return out
