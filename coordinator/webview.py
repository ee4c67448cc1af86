"""The web view of a run (``bmtree watch --web``, ``bmtree replay RUN --web``): a page served
by the standard library's http.server from a thread; the page (``coordinator/web/``, shipped
in the package, no CDN) long-polls ``/state`` and draws the tree as an SVG graph.

Live, ``/state?since=V`` answers when the :class:`WatchState` passes version V (or after
a few seconds; every second while the run's node does not answer: its ``silent`` says for how
long). For a recorded run, ``/state?at=SECONDS`` is the state at that moment of the log
(``at=end``: its end; the page shows a timeline slider), with what the page needs to know of the
whole run (``replay``: killed or not, when last seen alive, the failure that ended it).
``/control`` (POST) hands a command to the ``control`` callable, when there is one, and answers
with its reply.

A page that goes away mid-answer (a tab closed during a long poll) is no error: nothing is
printed. ``watch --web`` keeps serving the run's end after it, while no page has been sent it
(:data:`LINGER`, :meth:`WebServer.close`).
"""
from __future__ import annotations

import errno
import json
import os
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Callable, Dict, Optional, TextIO
from urllib.parse import parse_qs, urlparse

from comm.address import advertised
from comm.nodelife import stop_requested
from coordinator.runstream import to_json
from coordinator.watchstate import WatchState

__all__ = ["WebServer", "serve", "replay_states", "replay_meta", "LINGER"]

WEB_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "web")
FILES = {"/": ("index.html", "text/html; charset=utf-8"), "/index.html": ("index.html", "text/html; charset=utf-8"),
         "/app.js": ("app.js", "text/javascript; charset=utf-8"), "/style.css": ("style.css", "text/css; charset=utf-8")}
MAX_BODY = 64 * 1024
#: how long a live ``/state`` waits for a change before it answers anyway (s)
POLL_WAIT = 8.0
#: ``watch --web``: after the run's end, how long the page is still served while no page has been
#: sent that end (s): a page opened late still shows how the run ended (Ctrl-C ends it sooner)
LINGER = 600.0
#: a page that went away before its answer was written (a tab closed during a long poll)
GONE_PAGE = (BrokenPipeError, ConnectionResetError, ConnectionAbortedError)


class _Server(ThreadingHTTPServer):
    daemon_threads = True

    def handle_error(self, request: Any, client_address: Any) -> None:
        if isinstance(sys.exc_info()[1], GONE_PAGE):  # the page closed: nothing to tell the terminal
            return
        super().handle_error(request, client_address)


class WebServer:
    """The page and its JSON, served from a daemon thread until :meth:`close`."""

    def __init__(self, state: Optional[WatchState], bind: str = "127.0.0.1", port: int = 0,
                 at: Optional[Callable[[float], Dict[str, Any]]] = None, duration: float = 0.0,
                 control: Optional[Callable[[Dict[str, Any]], Dict[str, Any]]] = None,
                 replay: Optional[Dict[str, Any]] = None, linger: float = 0.0, out: Optional[TextIO] = None):
        self.state = state
        self.at = at
        self.duration = duration
        self.control = control
        #: a recorded run: what the page shows of the whole run (:func:`replay_meta`)
        self.replay = replay or {}
        #: seconds :meth:`close` keeps serving a live run's end that no page has been sent yet
        self.linger = linger
        self.poll_wait = POLL_WAIT
        self.out = out
        #: set once a page has been answered with the run's end (``watch --web`` may then end)
        self.end_served = threading.Event()
        server = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, fmt: str, *args: Any) -> None:  # quiet: the terminal is the user's
                return

            def _send(self, code: int, body: bytes, ctype: str) -> None:
                try:
                    self.send_response(code)
                    self.send_header("Content-Type", ctype)
                    self.send_header("Content-Length", str(len(body)))
                    self.send_header("Cache-Control", "no-store")
                    self.end_headers()
                    self.wfile.write(body)
                except GONE_PAGE:  # the page went away (its tab closed mid long-poll): not an error
                    self.close_connection = True

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
                why = server.state.no_steering() if server.state is not None else ""
                if why:  # nothing would take it (no run shown yet, one without --control, or ended): not sent
                    self._json(200, {"ok": False, "answer": "not sent: %s" % why})
                    return
                self._json(200, server.control(cmd))

        try:
            self.httpd = _Server((bind, port), Handler)
        except OSError as exc:
            if exc.errno != errno.EADDRINUSE:
                raise
            raise OSError("port %d on %s is taken (another bmtree watch --web or replay --web?): give --port 0 "
                          "for any free port, or another --port" % (port, bind)) from None
        host, real_port = self.httpd.server_address[:2]
        self.url = "http://%s:%d/" % ("127.0.0.1" if host in ("0.0.0.0", "") else host, real_port)
        #: how other machines reach the page when it listens on every address: as they reach this
        #: machine's ROS nodes (ROS_HOSTNAME, ROS_IP, else its host name)
        self.remote_url = ""
        if host in ("0.0.0.0", ""):
            name = advertised().host
            if name and name not in ("localhost", "127.0.0.1") and not name.startswith("localhost."):
                self.remote_url = "http://%s:%d/" % (name, real_port)
        self._thread = threading.Thread(target=self.httpd.serve_forever, name="bmtree-web", daemon=True)
        self._thread.start()

    def state_for(self, q: Dict[str, Any]) -> Dict[str, Any]:
        if self.at is not None:
            given = (q.get("at") or ["end"])[0]
            at = float("inf") if given == "end" else float(given)  # the end: the whole run, its end record included
            if at != at:
                raise ValueError("at is not a number")
            data = self.at(at)
            data.update(mode="replay", duration=self.duration, at=min(at, self.duration), replay=self.replay,
                        steer=False)  # a recording takes no commands
            if self.replay.get("unfinished") and at >= self.duration:  # killed: its end is when it was last alive
                data.update(end=self.replay.get("end"), t=max(float(data.get("t") or 0.0), self.duration),
                            pending=[dict(c, maybe_running=True) for c in data.get("pending") or []])  # nobody stopped them
            return data
        assert self.state is not None
        since = int((q.get("since") or ["-1"])[0])
        # while the run's node does not answer, every second: the page says for how long
        self.state.wait(lambda s: s.version != since, 1.0 if self.state.silence() else self.poll_wait)
        data = self.state.view()
        # control buttons only while the run shown takes commands: its tree record said so, it has not ended
        # (none before a run is shown: nothing would take them)
        data.update(mode="live", steer=self.control is not None and bool(data.get("steer")))
        if data.get("end"):
            self.end_served.set()
        return data

    def where(self) -> str:
        """The page's address as printed: the local one, and the one of other machines if it has one."""
        return self.url + (" (from other machines: %s)" % self.remote_url if self.remote_url else "")

    def close(self) -> None:
        """Stop serving; a live run's end that no page has been sent yet is served :attr:`linger`
        seconds more first (see :meth:`keep_serving_end`)."""
        try:
            self.keep_serving_end()
        finally:
            self.httpd.shutdown()
            self.httpd.server_close()

    def keep_serving_end(self) -> None:
        """While a live run has ended and no page has been sent that end: serve on until one is
        (and a second more, for the other pages polling), a stop signal (Ctrl-C) comes, or
        :attr:`linger` seconds pass. ``watch --web`` ends its own wait for a page 5 s after the run;
        an operator who opens the page later still sees how the run ended."""
        state = self.state
        if self.linger <= 0 or state is None or state.end is None or self.end_served.is_set() or stop_requested():
            return
        out = self.out or sys.stdout
        try:
            out.write("no page has shown the end yet: %s keeps serving it for up to %s (Ctrl-C ends)\n" % (
                self.where(), "%d min" % (self.linger // 60) if self.linger >= 120 else "%g s" % self.linger))
            out.flush()
        except (OSError, ValueError):  # no usable stdout: serve on all the same
            pass
        end = time.monotonic() + self.linger
        while time.monotonic() < end and not stop_requested():
            if self.end_served.wait(0.2):
                later = time.monotonic() + 1.0
                while time.monotonic() < later and not stop_requested():
                    time.sleep(0.1)
                return


def serve(state: WatchState, bind: str = "127.0.0.1", port: int = 0,
          control: Optional[Callable[[Dict[str, Any]], Dict[str, Any]]] = None, linger: float = LINGER) -> WebServer:
    """Serve ``state`` live on ``bind:port`` (0: any free port); once the run has ended, :meth:`WebServer.close`
    serves that end ``linger`` seconds more while no page has been sent it."""
    return WebServer(state, bind, port, control=control, linger=linger)


def replay_states(records: list, last_alive: Optional[float] = None) -> Callable[[float], Dict[str, Any]]:
    """For a recorded run: the view at any moment, by applying the log's records up to it.
    ``last_alive``: a killed run's (no end record) time when it was last seen alive, the time of
    its whole-run view (``at`` infinite) when that is after its last record."""
    lock = threading.Lock()

    def at(t: float) -> Dict[str, Any]:
        with lock:
            s = WatchState(recent=0)  # a log's records, in order
            for rec in records:
                if rec.get("type") != "tree" and float(rec.get("t") or 0.0) > t:
                    break
                s.apply(rec)
            if t == float("inf"):
                s.t = max(s.t, last_alive or 0.0) if s.end is None else s.t
            else:
                s.t = t
            return s.view()

    return at


def replay_meta(log: Any) -> Dict[str, Any]:
    """What the page shows of a whole recorded run (:class:`coordinator.runlog.RunLog`): its length
    (``duration``: a killed run's is until it was last seen alive, as ``bmtree runs`` lists it),
    whether it was killed (``unfinished``, with the ``end`` the page shows for it: status
    UNFINISHED), and the failure that ended it (``failure``: its node, time and message, where
    ``bmtree replay --failure`` jumps), or None."""
    from coordinator.replay import Replay
    from coordinator.runlog import RunLogError

    end = log.end
    duration = float(log.last_alive)
    meta: Dict[str, Any] = {"duration": duration, "unfinished": end is None, "last_alive": duration,
                            "truncated": bool(log.truncated), "failure": None, "end": None}
    started = log.tree.get("started")
    if end is None:
        wall = ""
        if isinstance(started, (int, float)) and started:
            wall = " (%s)" % time.strftime("%H:%M:%S", time.localtime(started + duration))
        meta["end"] = {"v": 1, "type": "end", "run": log.tree.get("run"), "t": duration, "status": "UNFINISHED",
                       "gone": True, "duration": duration, "ticks": len(log.of_type("tick")),
                       "reason": "its log has no end record: the process was killed (or lost power); last seen "
                                 "alive at %.2fs%s%s" % (duration, wall, ", its last record cut" if log.truncated else "")}
    try:
        replay = Replay(log)
        ended, _others = replay.failures()
    except (RunLogError, TypeError, ValueError, KeyError, IndexError, AttributeError):
        return meta  # a log it cannot follow: no jump, the timeline still works
    if ended is not None:
        meta["failure"] = {"t": ended.t, "node": ended.node, "name": str(replay.nodes.get(ended.node, {}).get("name", "?")),
                           "message": ended.message, "within": ended.within}
    return meta


def cmd_replay_web(args: Any) -> int:
    """``bmtree replay RUN --web``: the recorded run on the page, with a timeline to scrub."""
    from coordinator.replay import read_run

    log = read_run(args.run, args.dir)   # (the lines it skips are said on stderr)
    path = log.path
    meta = replay_meta(log)
    server = WebServer(None, args.bind, args.port, at=replay_states(list(log.records), meta["duration"]),
                       duration=meta["duration"], replay=meta)
    print("replay of %s%s; page at %s (Ctrl-C stops)" % (
        path, " (UNFINISHED: its log has no end)" if meta["unfinished"] else "", server.where()))
    sys.stdout.flush()
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        return 0
    finally:
        server.close()
