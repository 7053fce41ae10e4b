"""The cases of a sweep on Dask distributed: an embedded local cluster, or a running scheduler.

`run_sweep` expands the spec, skips the cases the results table already holds (resume), submits the
rest as Dask tasks and writes ``DIR/results.parquet`` as they finish (atomically, at most every
``flush_s`` seconds and at the end, also on Ctrl-C). A table that cannot be written (a full disk)
leaves the last one whole, and the sweep's result then carries every row instead. A case that
raises is recorded with its error (`bench.workflows.sweep.cases.run_case` never raises); a worker that dies
mid-case gets one retry (the scheduler's ``allowed-failures`` = 1), then the case is recorded as an
error.

Local cluster: ``workers`` processes, one thread each, bound to 127.0.0.1, and every connection TLS with a
certificate made for this cluster alone (`distributed.security.Security.temporary`, mutual: a client or
worker must present it). Plain TCP on 127.0.0.1 would let any local user connect to the scheduler and run
code in the workers, as the sweep's user. The scheduler and each worker always start an HTTP server of their
own (Dask's status pages, metrics, health; the dashboard with bokeh): here it speaks HTTPS with the same
certificate (Dask's ``distributed.scheduler.dashboard.tls`` settings, read by every server of the cluster), and
by default it serves no page and is closed as soon as the cluster is up (`Cluster`: no dashboard port open; a
worker the nanny restarts opens one again, HTTPS, serving nothing). With ``dashboard`` the scheduler's
serves the status pages on 127.0.0.1 (``DASHBOARD_PORT``, or a free port), HTTPS only. Any other cluster:
``scheduler="tls://host:8786"`` (or ``tcp://`` on a trusted network; e.g. dask-jobqueue's
SLURMCluster, docs/sweeps.md); its workers need imbench installed, and the retry count is that
scheduler's own setting.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from bench.errors import BadInput
from bench.core.outputs import write_text
from bench.workflows.sweep import table
from bench.workflows.sweep.cases import Case, error_row, expand, run_case
from bench.workflows.sweep.spec import LARGE_CASES, SweepSpec, count
from bench.core.shutdown import COMMAND_SIGNALS, Interrupted
from bench.core.progress import Steps, stages
from bench.workflows.sweep.tasks import run_task
from bench.workflows.sweep.batching import group, run_group
from bench.drivers.riglock import runtime_dir

CONNECT_TIMEOUT = 10.0  # [s] to reach a scheduler
DASHBOARD_PORT = 8787  # the local cluster's dashboard (--dashboard), on 127.0.0.1; taken: any free port
FLUSH_S = 2.0  # [s] between table writes while cases finish


def _writable(out: Path) -> None:
    """Refuse an output folder that is a file or cannot be created or written (creates nothing)."""
    if out.exists() and not out.is_dir():
        raise BadInput("--out", f"{out} is a file; give a folder")
    parent = out
    while not parent.exists():
        parent = parent.parent
    if not os.access(parent, os.W_OK | os.X_OK):
        raise BadInput("--out", f"cannot write in {parent}")


def _previous(out: Path, cases: list[Case]) -> tuple[list[dict[str, Any]], int]:
    """Rows of an earlier run of this sweep in ``out`` (finished ones are kept, errors run again), and
    how many rows the table held."""
    path = out / table.RESULTS
    if not path.exists():
        return [], 0
    rows = table.read(path)
    ids = {c.case_id for c in cases}
    foreign = [r["case_id"] for r in rows if r["case_id"] not in ids]
    if foreign:
        raise BadInput("--out", f"{out} holds {len(foreign)} case(s) of another sweep (e.g. {foreign[0]}); "
                       "give a new folder")  # fmt: skip
    # one row per case: a table with a case twice (two runs that wrote it, an edit by hand) keeps its last
    finished = {r["case_id"]: r for r in rows if r["status"] in ("ok", "tripped")}
    return list(finished.values()), len(rows)


@contextlib.contextmanager
def _sigint_held() -> Iterator[None]:
    """SIGINT blocked in this thread while the local cluster's processes are started: the threads that start them,
    and so the workers, inherit the mask (it survives fork and exec; `bench.workflows.sweep.worker_setup` then ignores
    it there).

    A Ctrl-C at the terminal goes to the whole process group; the workers would each print a KeyboardInterrupt
    traceback. This process handles it (the table is written, the cluster closed): one that comes while the cluster
    starts waits until the mask is restored (it was ignored, and lost, before: the sweep went on).
    """
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()  # (started later, it would unblock SIGINT in the thread that starts it)
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


@contextlib.contextmanager
def _signals_noted(got: list[int]) -> Iterator[None]:
    """Note in ``got`` each of the command signals (SIGINT, SIGTERM, SIGHUP) that this process handles, then handle it
    as before (the CLI's `bench.core.shutdown.SignalGuard` raises `Interrupted`). That exception is lost where the
    signal finds the main thread in a garbage-collector callback or a ``__del__`` (Dask's client has both; Python only
    prints it), and the guard takes no second one: the sweep checks ``got`` while it waits for results."""
    saved: dict[int, Any] = {}

    def noted(signum: int, frame: Any) -> None:
        got.append(signum)
        saved[signum](signum, frame)

    if threading.current_thread() is threading.main_thread():
        for s in COMMAND_SIGNALS:
            if callable(signal.getsignal(s)):  # (one ignored or left to the default stays so)
                saved[s] = signal.signal(s, noted)
    try:
        yield
    finally:
        for s, old in saved.items():
            signal.signal(s, old)


class Cluster:
    """A Dask client on an embedded local cluster or on ``scheduler``; a context manager. ``dashboard``: the local
    cluster serves its status pages over HTTPS on 127.0.0.1 (`dashboard_url`; module docstring)."""

    def __init__(self, workers: int | None = 2, scheduler: str | None = None, *, keep_logs: bool = False,
                 connect_timeout: float = CONNECT_TIMEOUT, dashboard: bool = False) -> None:  # fmt: skip
        if scheduler is not None and workers is not None:
            raise BadInput("--workers", "give --workers (local cluster) or --scheduler, not both")
        if scheduler is None and (workers is None or not 1 <= workers <= 256):
            raise BadInput("--workers", f"must be in 1..256, got {workers}")
        if scheduler is not None and not scheduler.startswith(("tcp://", "tls://", "inproc://")):
            raise BadInput("--scheduler", f"a scheduler address like tcp://host:8786, got {scheduler!r}")
        if dashboard and scheduler is not None:
            raise BadInput("--dashboard", "only with the local cluster (a running scheduler serves its own)")
        self.workers, self.scheduler, self.keep_logs = workers, scheduler, keep_logs
        self.connect_timeout = connect_timeout
        self.dashboard = dashboard
        self.dashboard_url: str | None = None  # https://127.0.0.1:PORT/ once the local cluster serves it
        self.client: Any = None
        self.cluster: Any = None
        self._config: Any = None
        self._certs: Path | None = None  # the cluster's certificate and key as files, for its HTTPS servers

    def __enter__(self) -> "Cluster":
        import dask
        from distributed import Client, LocalCluster
        from distributed.security import Security

        # one retry for a task whose worker died under it; workers may start processes (the log
        # writer of --keep-logs) only if they are not daemonic; the local workers' statistical profiler
        # (a stack sample every 10 ms, for the dashboard's profile page) takes the GIL from the cases, which
        # are pure-Python loops
        settings: dict[str, Any] = {"distributed.scheduler.allowed-failures": 1,
                                    "distributed.worker.daemon": not self.keep_logs,
                                    "distributed.worker.profile.enabled": False,
                                    "distributed.admin.system-monitor.gil.enabled": False}  # fmt: skip
        try:
            if self.scheduler is None:
                # TLS, mutual, with a throw-away CA and certificate (in memory, handed to the workers when they
                # start): only this process and its workers hold the key (docs/sweeps.md); the HTTP servers read
                # theirs from files (this user's runtime folder, mode 0700; removed when the cluster closes)
                security = Security.temporary()
                settings.update(self._https(security))
            self._config = dask.config.set(settings)
            self._config.__enter__()
            if self.scheduler is None:
                with _sigint_held(), warnings.catch_warnings():  # Ctrl-C: see _sigint_held
                    # the scheduler's HTTP server takes 8787 on 127.0.0.1, or any free port
                    warnings.filterwarnings("ignore", message=f"Port {DASHBOARD_PORT} is already in use")
                    where = f"127.0.0.1:{DASHBOARD_PORT}" if self.dashboard else None
                    self.cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                                host="127.0.0.1", dashboard_address=where, protocol="tls://",
                                                security=security, silence_logs=logging.ERROR)  # fmt: skip
                self.client = Client(self.cluster)
                from bench.workflows.sweep.worker_setup import LocalWorker

                self.client.register_plugin(LocalWorker())  # SIGINT ignored, Dask's closing noise dropped
                if self.dashboard:
                    self.dashboard_url = f"https://127.0.0.1:{self.cluster.scheduler.http_server.port}/"
                else:  # no page to serve: close the servers' ports
                    self.client.run_on_scheduler(_stop_http_server)
                    self.client.run(_stop_http_server)
            else:
                try:
                    self.client = Client(self.scheduler, timeout=self.connect_timeout)
                except (OSError, TimeoutError, ValueError) as exc:
                    raise BadInput("--scheduler", f"cannot reach {self.scheduler}: {exc}") from None
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _https(self, security: Any) -> dict[str, Any]:
        """The Dask settings that make every HTTP server of the local cluster HTTPS with ``security``'s certificate
        (the workers get them from their nanny), serving nothing unless `dashboard` (and never Dask's proxy to
        other ports)."""
        import tempfile


        self._certs = Path(tempfile.mkdtemp(prefix="dask-https-", dir=runtime_dir()))  # mode 0700
        files = {}
        for name, text in (("cert", security.tls_scheduler_cert), ("key", security.tls_scheduler_key)):
            files[name] = self._certs / f"{name}.pem"
            fd = os.open(files[name], os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
            with os.fdopen(fd, "w") as f:
                f.write(text)
        out: dict[str, Any] = {"distributed.scheduler.dashboard.tls.cert": str(files["cert"]),
                               "distributed.scheduler.dashboard.tls.key": str(files["key"])}  # fmt: skip
        if self.dashboard:
            import dask

            routes = dask.config.get("distributed.scheduler.http.routes")
            out["distributed.scheduler.http.routes"] = [r for r in routes if r != "distributed.http.proxy"]
        else:
            out["distributed.scheduler.http.routes"] = []
            out["distributed.worker.http.routes"] = []
        return out

    def n_workers(self) -> int:
        return len(self.client.scheduler_info(n_workers=-1).get("workers", {})) if self.client else 0

    def __exit__(self, *exc: object) -> None:
        for thing in (self.client, self.cluster):
            if thing is not None:
                with contextlib.suppress(Exception):
                    thing.close()
        self.client = self.cluster = None
        if self._config is not None:
            self._config.__exit__(None, None, None)
            self._config = None
        if self._certs is not None:
            import shutil

            shutil.rmtree(self._certs, ignore_errors=True)
            self._certs = None


def _stop_http_server(dask_scheduler: Any = None, dask_worker: Any = None) -> None:
    """On the scheduler (`Client.run_on_scheduler`) or a worker (`Client.run`), in its event loop: close its HTTP
    server's port (`Cluster` without a dashboard)."""
    server = dask_scheduler if dask_scheduler is not None else dask_worker
    server.http_server.stop()


def _stop_if(signalled: list[int]) -> None:
    """Raise `Interrupted` for a signal noted by `_signals_noted` (its own exception was lost on the way)."""
    if signalled:
        raise Interrupted(signalled[0])


def _save(path: Path, rows: list[dict[str, Any]]) -> str | None:
    """Write the table; on failure (a full disk) return why: the sweep goes on, the old table stays whole."""
    try:
        table.write(path, rows)
        return None
    except OSError as exc:
        return exc.strerror or str(exc)


def _prepare_folder(out: Path, spec: SweepSpec, n_cases: int, keep_logs: bool,
                    runner: Callable[..., dict[str, Any]] | None) -> tuple[Callable[..., Any], Path | None]:  # fmt: skip
    """The sweep's folder before any case runs: its spec and description (a folder that cannot take them is
    refused in one line) and the cases' log folder; returns the function a worker calls and that folder."""
    log_dir = None
    if spec.task:
        runner = runner or run_task
        log_dir = out / "tasks"
        log_dir.mkdir(exist_ok=True)
    elif keep_logs:
        log_dir = out / "logs"
        log_dir.mkdir(exist_ok=True)
    runner = runner or run_case
    what = {"task": spec.task} if spec.task else {"rig": spec.rig, "controller": spec.controller}
    try:
        write_text(out / "spec.toml", spec.source)
        write_text(out / table.SWEEP_JSON, json.dumps({"name": spec.name, "description": spec.description,
                                                       "cases": n_cases, **what}, indent=2) + "\n")  # fmt: skip
    except OSError as exc:
        raise BadInput("--out", f"cannot write in {out}: {exc.strerror or exc}") from None
    return runner, log_dir


def _submit(client: Any, pending: list[Case], runner: Callable[..., Any], log_dir: Path | None, n_workers: int,
            batch: int) -> tuple[list[Any], dict[str, Case | list[Case]]]:  # fmt: skip
    """Every pending case to the cluster: with ``batch`` > 0 those the batch engine takes in groups of up to that
    many per task (`bench.workflows.sweep.batching`), the others one per task; the futures and what each one runs."""
    by_key: dict[str, Case | list[Case]] = {}
    futures = []
    singles = pending
    if batch > 0:
        groups, singles = group(pending, batch, n_workers)
        for g in groups:
            f = client.submit(run_group, g, None, key=f"bench-sweep-batch-{g[0].case_id}-{len(g)}", pure=False)
            by_key[f.key] = g
            futures.append(f)
    for c in singles:
        f = client.submit(runner, c, str(log_dir) if log_dir else None, key=f"bench-sweep-{c.case_id}", pure=False)
        by_key[f.key] = c
        futures.append(f)
    return futures, by_key


def _collect(futures: list[Any], by_key: dict[str, Case | list[Case]], rows: list[dict[str, Any]], stored: int,
             out: Path, flush_s: float, signalled: list[int], bar: Any) -> tuple[list[dict[str, Any]], str | None]:  # fmt: skip
    """The rows as the cases finish (a task that failed is an error row of each of its cases), the table written
    every ``flush_s`` and at the end, Ctrl-C included; returns the new rows and why the last table write failed
    (None: it did not)."""
    from distributed import as_completed  # the sweep's parent imports Dask only where it runs one

    new: list[dict[str, Any]] = []
    unsaved: str | None = None
    last_flush = time.monotonic()
    try:
        with bar if bar is not None else contextlib.nullcontext(lambda n: None) as step:
            results = as_completed(futures)
            while not results.is_empty():
                _stop_if(signalled)
                if not results.has_ready():
                    time.sleep(0.05)
                    continue
                f = next(results)
                c = by_key[f.key]
                try:
                    got = f.result()
                except Exception as exc:  # noqa: BLE001 - KilledWorker (died twice), lost scheduler, ...
                    what = type(exc).__name__
                    why = "the worker died twice running this case" if what == "KilledWorker" else str(exc)
                    got = [{**x.inputs(), **error_row(f"{what}: {why}")} for x in (c if isinstance(c, list) else [c])]
                new.extend(got if isinstance(got, list) else [got])  # a batch's task: its cases' rows
                f.release()
                step(len(new))
                if time.monotonic() - last_flush >= flush_s:
                    unsaved = _save(out / table.RESULTS, rows + new)
                    last_flush = time.monotonic()
    finally:  # Ctrl-C too: the table holds every case that finished
        for f in futures:
            if not f.done():
                f.cancel()
        if new or len(rows) != stored or not (out / table.RESULTS).exists():  # duplicates go too
            unsaved = _save(out / table.RESULTS, rows + new)
    return new, unsaved


def run_sweep(spec: SweepSpec, out: Path, *, workers: int | None = 2, scheduler: str | None = None,
              keep_logs: bool = False, progress: bool = True, client: Any = None, flush_s: float = FLUSH_S,
              runner: Callable[..., dict[str, Any]] | None = None,
              connect_timeout: float = CONNECT_TIMEOUT, allow_large: bool = False,
              say: Callable[[str], None] | None = None, batch: int = 0, dashboard: bool = False) -> dict[str, Any]:  # fmt: skip
    """Run the sweep into ``out``; returns its summary (cases, skipped, ok, tripped, errors, throughput).

    ``client``: an existing Dask client (then ``workers``/``scheduler`` are ignored). ``runner``: the
    function a worker calls with (case, folder) - `run_case` (folder: logs of --keep-logs) for sessions,
    `bench.workflows.sweep.tasks.run_task` (folder: ``DIR/tasks``, each case its own subfolder) for a task sweep,
    unless a test replaces it. More than `LARGE_CASES` cases run only with ``allow_large``. ``say``
    gets one line: how many cases there are and how many run. ``batch`` > 0: the cases the batch engine
    takes run up to that many per task in one compiled loop (`bench.workflows.sweep.batching`; not with
    ``keep_logs`` or a ``runner``). ``dashboard``: the local cluster serves its status pages (`Cluster`), their
    address said on stderr (through ``say``).
    """
    n = count(spec)
    if n > LARGE_CASES and not allow_large:
        raise BadInput("--allow-large", f"the sweep has {n} cases, more than {LARGE_CASES}; pass --allow-large "
                       "to run them all")  # fmt: skip
    cases = expand(spec)
    _writable(out)
    rows, stored = _previous(out, cases)
    done = {r["case_id"] for r in rows}
    pending = [c for c in cases if c.case_id not in done]
    ctx = contextlib.nullcontext() if client is not None else Cluster(None if scheduler else workers, scheduler,
                                                                       keep_logs=keep_logs,
                                                                       connect_timeout=connect_timeout,
                                                                       dashboard=dashboard)  # fmt: skip
    if say is not None:
        say(f"sweep {spec.name}: {len(cases)} cases" + (f", {len(done)} done before, {len(pending)} to run"
                                                        if done else ""))  # fmt: skip
    tell = say or (lambda line: print(f"bench: {line}", file=sys.stderr, flush=True))
    t0 = time.perf_counter()
    say = stages(f"sweep {spec.name}") if progress else lambda text: None
    if client is None:  # Dask takes seconds to start (~12 s for 2 local workers on 2 cores): say so
        say(f"connecting to the Dask scheduler {scheduler} ..." if scheduler else
            f"starting a local Dask cluster ({workers} worker processes) ...")  # fmt: skip
    signalled: list[int] = []  # (_signals_noted)
    with _signals_noted(signalled), ctx as cl:
        _stop_if(signalled)
        if cl is not None and cl.dashboard_url:
            tell(f"dashboard: {cl.dashboard_url} (127.0.0.1 only, HTTPS with the cluster's own throw-away certificate: "
                 "the browser asks once)")  # fmt: skip
        client = client if client is not None else cl.client
        n_workers = len(client.scheduler_info(n_workers=-1).get("workers", {}))
        earlier = f" ({len(done)} done in an earlier run)" if done else ""
        say(f"{n_workers} workers ready; {len(pending)} of {len(cases)} cases to run{earlier}; the first results "
            "take longest (each worker imports and compiles first)")  # fmt: skip
        out.mkdir(parents=True, exist_ok=True)  # from here on, the folder is ours
        runner, log_dir = _prepare_folder(out, spec, len(cases), keep_logs, runner)
        futures, by_key = _submit(client, pending, runner, log_dir, n_workers,
                                  batch if batch > 0 and not spec.task and not keep_logs and runner is run_case else 0)
        new, unsaved = _collect(futures, by_key, rows, stored, out, flush_s, signalled,
                                Steps(len(pending), f"sweep {spec.name}") if progress else None)  # fmt: skip
    wall = time.perf_counter() - t0
    ran = new
    sim = sum(r.get("sim_time") or 0.0 for r in ran)
    counts = {s: sum(r["status"] == s for r in ran) for s in ("ok", "tripped", "error")}
    if unsaved is not None:  # the rows are not lost: they go back to the caller (bench sweep prints them)
        return {"sweep": spec.name, "results": None, "table_error": f"{out / table.RESULTS} not written: {unsaved}",
                "cases": len(cases), "skipped": len(done), "ran": len(ran), **counts, "rows": rows + new}
    return {"sweep": spec.name, "results": str(out / table.RESULTS), "cases": len(cases), "skipped": len(done),
            "ran": len(ran), **counts, "workers": n_workers, "wall_time_s": wall,
            "cases_per_minute": 60.0 * len(ran) / wall if ran else None,
            "sim_seconds_per_wall_second": sim / wall if ran and not spec.task else None}  # fmt: skip
