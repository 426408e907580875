"""A meshcat server bound to one address, that dies with the process that started it.

``python -m meshcat.servers.zmqserver`` serves its web page on every interface and outlives a
parent stopped by SIGTERM or a kill. This runs the same server (meshcat's own
``ZMQWebSocketBridge``) with the web page bound to ``--host`` (default 127.0.0.1), and stops it
when its parent process is gone. :func:`start` launches it and returns its URLs.

Run as ``python -m coopdyn.viz.meshcat_server [--host HOST]``.
"""

from __future__ import annotations

import argparse
import ipaddress
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from typing import Any

from ..errors import ViewerError

LOOPBACK = "127.0.0.1"


def is_loopback(host: str) -> bool:
    """Whether ``host`` is only reachable from this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_host(host: object) -> str:
    """``host`` as an address meshcat's server can bind: an IPv4 address or a host name."""
    if not isinstance(host, str) or not host or any(c.isspace() for c in host):
        raise ViewerError(f"host must be an address such as '127.0.0.1', got {host!r}")
    if ":" in host:
        raise ViewerError(f"host {host!r}: meshcat's server binds IPv4 addresses or host names only; use 127.0.0.1")
    return host


@dataclass
class Server:
    """A running server: its process and the URLs to reach it."""

    process: subprocess.Popen[bytes]
    zmq_url: str
    web_url: str

    def stop(self) -> None:
        """Stop the server (idempotent)."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


def start(host: str = LOOPBACK) -> Server:
    """Start a server bound to ``host`` in a child process; returns once it listens."""
    host = check_host(host)
    proc = subprocess.Popen(
        [sys.executable, "-u", "-m", "coopdyn.viz.meshcat_server", "--host", host, "--parent", str(os.getpid())],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    try:
        return _started(proc)
    except BaseException:  # Ctrl-C or a failure while it starts: no server left behind
        proc.kill()
        proc.wait()
        raise


def _started(proc: subprocess.Popen[bytes]) -> Server:
    urls: dict[str, str] = {}
    assert proc.stdout is not None
    while len(urls) < 2:
        line = proc.stdout.readline().decode("utf-8", "replace").strip()
        if not line and proc.poll() is not None:
            err = proc.stderr.read().decode("utf-8", "replace") if proc.stderr else ""
            raise ViewerError(f"the meshcat server could not start (exit code {proc.returncode}): {err.strip()[-500:]}")
        m = re.match(r"(zmq_url|web_url)=(\S+)", line)
        if m:
            urls[m.group(1)] = m.group(2)
    return Server(proc, urls["zmq_url"], urls["web_url"])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--host", default=LOOPBACK, help="address to serve on (default 127.0.0.1: this machine only)")
    parser.add_argument("--parent", type=int, default=None, help="stop when this process is gone")
    args = parser.parse_args(argv)
    import tornado.ioloop
    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    class Bridge(ZMQWebSocketBridge):
        def make_app(self) -> Any:
            app = super().make_app()
            listen = app.listen
            app.listen = lambda port, **kw: listen(port, address=self.host, **kw)  # the web page on host only
            return app

    bridge = Bridge(host=args.host)
    print(f"zmq_url={bridge.zmq_url}")
    print(f"web_url={bridge.web_url}", flush=True)
    # Nobody reads our output from here on (meshcat logs every connection): a full pipe would
    # block the server, so it goes nowhere.
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    if args.parent is not None:

        def orphaned() -> None:
            if os.getppid() != args.parent:  # re-parented: the process that started us is gone
                bridge.ioloop.stop()

        tornado.ioloop.PeriodicCallback(orphaned, 500).start()
    try:
        bridge.run()
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
