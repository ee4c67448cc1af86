"""The web view of a run (``bmtree watch --web``, ``bmtree replay RUN --web``): a page served
by the standard library's http.server from a thread; the page (``coordinator/web/``, shipped
in the package, no CDN) long-polls ``/state`` and draws the tree as an SVG graph.

Live, ``/state?since=V`` answers when the :class:`WatchState` passes version V (or after
a few seconds). For a recorded run, ``/state?at=SECONDS`` is the state at that moment of
the log (the page shows a timeline slider). ``/control`` (POST) hands a command to the
``control`` callable, when there is one, and answers with its reply.
"""
from __future__ import annotations

import json
import os
import socket
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Callable, Dict, Optional
from urllib.parse import parse_qs, urlparse

from coordinator.runstream import to_json
from coordinator.watchstate import WatchState

__all__ = ["WebServer", "serve", "replay_states"]

WEB_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "web")
FILES = {"/": ("index.html", "text/html; charset=utf-8"), "/index.html": ("index.html", "text/html; charset=utf-8"),
         "/app.js": ("app.js", "text/javascript; charset=utf-8"), "/style.css": ("style.css", "text/css; charset=utf-8")}
MAX_BODY = 64 * 1024


class WebServer:
    """The page and its JSON, served from a daemon thread until :meth:`close`."""

    def __init__(self, state: Optional[WatchState], bind: str = "127.0.0.1", port: int = 0,
                 at: Optional[Callable[[float], Dict[str, Any]]] = None, duration: float = 0.0,
                 control: Optional[Callable[[Dict[str, Any]], Dict[str, Any]]] = None):
        self.state = state
        self.at = at
        self.duration = duration
        self.control = control
        #: set once a page has been answered with the run's end (``watch --web`` may then end)
        self.end_served = threading.Event()
        server = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, fmt: str, *args: Any) -> None:  # quiet: the terminal is the user's
                return

            def _send(self, code: int, body: bytes, ctype: str) -> None:
                self.send_response(code)
                self.send_header("Content-Type", ctype)
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                self.wfile.write(body)

            def _json(self, code: int, data: Dict[str, Any]) -> None:
                self._send(code, to_json(data).encode("utf-8"), "application/json")

            def do_GET(self) -> None:  # noqa: N802 - http.server's name
                url = urlparse(self.path)
                if url.path in FILES:
                    name, ctype = FILES[url.path]
                    with open(os.path.join(WEB_DIR, name), "rb") as fh:
                        self._send(200, fh.read(), ctype)
                elif url.path == "/state":
                    q = parse_qs(url.query)
                    try:
                        self._json(200, server.state_for(q))
                    except ValueError as exc:
                        self._json(400, {"error": str(exc)})
                else:
                    self._json(404, {"error": "no such page: %s" % url.path})

            def do_POST(self) -> None:  # noqa: N802
                if urlparse(self.path).path != "/control":
                    self._json(404, {"error": "no such page"})
                    return
                if server.control is None:
                    self._json(200, {"ok": False, "answer": "this view cannot steer (a replay, or a watcher "
                                                             "without a run that allows --control)"})
                    return
                try:
                    size = int(self.headers.get("Content-Length") or 0)
                    if size > MAX_BODY:
                        raise ValueError("the command is larger than %d bytes" % MAX_BODY)
                    cmd = json.loads(self.rfile.read(size).decode("utf-8"))
                    if not isinstance(cmd, dict):
                        raise ValueError("a command is a JSON object")
                except (ValueError, UnicodeDecodeError) as exc:
                    self._json(400, {"ok": False, "answer": "bad command: %s" % exc})
                    return
                self._json(200, server.control(cmd))

        self.httpd = ThreadingHTTPServer((bind, port), Handler)
        self.httpd.daemon_threads = True
        host, real_port = self.httpd.server_address[:2]
        self.url = "http://%s:%d/" % ("127.0.0.1" if host in ("0.0.0.0", "") else host, real_port)
        #: how other machines reach the page when it listens on every address (ROS_IP or
        #: ROS_HOSTNAME, as the machine's ROS nodes are reached, else its host name)
        self.remote_url = ""
        if host in ("0.0.0.0", ""):
            name = os.environ.get("ROS_IP") or os.environ.get("ROS_HOSTNAME") or socket.getfqdn()
            if name and name not in ("localhost", "127.0.0.1") and not name.startswith("localhost."):
                self.remote_url = "http://%s:%d/" % (name, real_port)
        self._thread = threading.Thread(target=self.httpd.serve_forever, name="bmtree-web", daemon=True)
        self._thread.start()

    def state_for(self, q: Dict[str, Any]) -> Dict[str, Any]:
        if self.at is not None:
            given = q.get("at")
            at = float(given[0]) if given else float("inf")  # none: the whole run, its end included
            if at != at:
                raise ValueError("at is not a number")
            data = self.at(at)
            data.update(mode="replay", duration=self.duration, at=min(at, self.duration))
            return data
        assert self.state is not None
        since = int((q.get("since") or ["-1"])[0])
        self.state.wait(lambda s: s.version != since, 8.0)
        data = self.state.view()
        data.update(mode="live", steer=self.control is not None and (data.get("tree") or {}).get("control") is not False)
        if data.get("end"):
            self.end_served.set()
        return data

    def where(self) -> str:
        """The page's address as printed: the local one, and the one of other machines if it has one."""
        return self.url + (" (from other machines: %s)" % self.remote_url if self.remote_url else "")

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


def serve(state: WatchState, bind: str = "127.0.0.1", port: int = 0,
          control: Optional[Callable[[Dict[str, Any]], Dict[str, Any]]] = None) -> WebServer:
    """Serve ``state`` live on ``bind:port`` (0: any free port)."""
    return WebServer(state, bind, port, control=control)


def replay_states(records: list) -> Callable[[float], Dict[str, Any]]:
    """For a recorded run: the view at any moment, by applying the log's records up to it."""
    lock = threading.Lock()

    def at(t: float) -> Dict[str, Any]:
        with lock:
            s = WatchState()
            for rec in records:
                if rec.get("type") != "tree" and float(rec.get("t") or 0.0) > t:
                    break
                s.apply(rec)
            s.t = min(t, s.t) if t == float("inf") else t
            return s.view()

    return at


def cmd_replay_web(args: Any) -> int:
    """``bmtree replay RUN --web``: the recorded run on the page, with a timeline to scrub."""
    import sys
    import time

    from coordinator.replay import find_run
    from coordinator.runlog import read_log

    path = find_run(args.run, args.dir)
    log = read_log(path)
    records = list(log.records)
    end = log.end or {}
    duration = float(end.get("duration") or (records[-1].get("t") if records else 0.0) or 0.0)
    server = WebServer(None, args.bind, args.port, at=replay_states(records), duration=duration)
    print("replay of %s; page at %s (Ctrl-C stops)" % (path, server.where()))
    sys.stdout.flush()
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        return 0
    finally:
        server.close()
