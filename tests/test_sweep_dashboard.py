"""The local sweep cluster's HTTP servers (bench.workflows.sweep.engine.Cluster): by default no port but Dask's TLS
comms is open, in the sweep's process and in its workers; with ``--dashboard`` the scheduler's status pages on
127.0.0.1, HTTPS with the cluster's certificate, and plain HTTP refused."""

from __future__ import annotations

import http.client
import os
import re
import ssl
import subprocess
import sys
from pathlib import Path

import psutil
import pytest

from bench.drivers.riglock import runtime_dir
from bench.workflows.sweep.engine import Cluster

ROOT = Path(__file__).resolve().parents[1]


def _listening(pids: list[int]) -> set[tuple[str, int]]:
    """The TCP ports the processes ``pids`` listen on, as (address, port)."""
    out = set()
    for pid in pids:
        for c in psutil.Process(pid).net_connections(kind="tcp"):
            if c.status == psutil.CONN_LISTEN:
                out.add((c.laddr.ip, c.laddr.port))
    return out


def _comms(cl: Cluster) -> set[tuple[str, int]]:
    """The cluster's Dask comm addresses (scheduler, workers, nannies) as (address, port)."""
    info = cl.client.scheduler_info(n_workers=-1)
    addrs = [info["address"], *info["workers"], *(w["nanny"] for w in info["workers"].values())]
    out = set()
    for a in addrs:
        assert a.startswith("tls://127.0.0.1:"), a
        host, port = a[len("tls://"):].rsplit(":", 1)
        out.add((host, int(port)))
    return out


def _cluster_pids(cl: Cluster) -> list[int]:
    return [os.getpid(), *cl.client.run(os.getpid).values()]


def _get(port: int, path: str, context: ssl.SSLContext | None = None) -> tuple[int, bytes]:
    conn = (http.client.HTTPSConnection("127.0.0.1", port, timeout=5, context=context) if context else
            http.client.HTTPConnection("127.0.0.1", port, timeout=5))  # fmt: skip
    try:
        conn.request("GET", path)
        r = conn.getresponse()
        return r.status, r.read()
    finally:
        conn.close()


def test_by_default_no_port_but_the_tls_comms_is_open() -> None:
    before = set(runtime_dir().glob("dask-https-*"))
    with Cluster(2) as cl:
        assert cl.dashboard_url is None
        assert cl.client.submit(sum, [1, 2]).result() == 3
        pids = _cluster_pids(cl)
        assert len(pids) == 3
        comms = _comms(cl)
        assert len(comms) == 5  # scheduler, 2 workers, 2 nannies
        assert _listening(pids) == comms  # no HTTP server port (Dask's opens 8787 and one per worker): closed
        made = set(runtime_dir().glob("dask-https-*")) - before
        assert len(made) == 1 and (next(iter(made)).stat().st_mode & 0o777) == 0o700
    assert set(runtime_dir().glob("dask-https-*")) == before  # the certificate's files go with the cluster


def test_the_dashboard_is_https_on_loopback_only() -> None:
    with Cluster(1, dashboard=True) as cl:
        m = re.fullmatch(r"https://127\.0\.0\.1:(\d+)/", cl.dashboard_url or "")
        assert m, cl.dashboard_url
        port = int(m.group(1))
        pids = _cluster_pids(cl)
        extra = _listening(pids) - _comms(cl)
        assert ("127.0.0.1", port) in extra and all(ip == "127.0.0.1" for ip, _ in extra)
        with pytest.raises((ConnectionError, http.client.HTTPException)):  # plain HTTP: no answer
            _get(port, "/health")
        insecure = ssl.create_default_context()
        insecure.check_hostname, insecure.verify_mode = False, ssl.CERT_NONE
        assert _get(port, "/health", insecure) == (200, b"ok")
        status, page = _get(port, "/info/main/workers.html", insecure)
        assert status == 200 and b"Workers" in page
        # the certificate is the cluster's own: its CA verifies it (name dask-internal), the system's does not
        (certs,) = [p for p in runtime_dir().glob("dask-https-*") if p == cl._certs]
        own = ssl.create_default_context(cafile=str(certs / "cert.pem"))
        own.check_hostname = False
        assert _get(port, "/health", own)[0] == 200
        with pytest.raises(ssl.SSLError):
            _get(port, "/health", ssl.create_default_context())


def test_dashboard_with_a_scheduler_is_refused() -> None:
    from bench.errors import BadInput

    with pytest.raises(BadInput, match="--dashboard: only with the local cluster"):
        Cluster(None, "tls://127.0.0.1:1", dashboard=True)


def test_bench_sweep_run_says_where_its_dashboard_is(tmp_path: Path) -> None:
    (tmp_path / "s.toml").write_text('[sweep]\nscenarios = ["fig5.7"]\nduration = 0.5\nseeds = [1]\n')
    p = subprocess.run([sys.executable, "-m", "bench", "sweep", "run", str(tmp_path / "s.toml"), "--out",
                        str(tmp_path / "out"), "--workers", "1", "--no-progress", "--dashboard"], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)  # fmt: skip
    assert p.returncode == 0, p.stderr[-3000:]
    lines = [ln for ln in p.stderr.splitlines() if "dashboard" in ln]
    assert len(lines) == 1 and re.match(r"bench: dashboard: https://127\.0\.0\.1:\d+/ \(127\.0\.0\.1 only, HTTPS",
                                        lines[0]), p.stderr  # fmt: skip
    q = subprocess.run([sys.executable, "-m", "bench", "sweep", "run", str(tmp_path / "s.toml"), "--out",
                        str(tmp_path / "out2"), "--scheduler", "tls://127.0.0.1:1", "--dashboard"], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert q.returncode == 2 and q.stderr.strip().splitlines() == [
        "bench: error: --dashboard: only with the local cluster (a running scheduler serves its own)"]
