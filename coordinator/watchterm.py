"""The terminal side of ``bmtree watch`` and ``bmtree run``: the live view redrawn in place on the
alternate screen, what stays on the normal screen once it ends, and the steering keys."""
from __future__ import annotations

import os
import sys
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Union

from coordinator.watchstate import WatchState
from coordinator.watchtext import summary_lines
from coordinator.watchview import now_since, render

__all__ = ["LiveView", "Keys", "key_reader", "keys_help", "KEYS_HELP", "NO_CONTROL_HELP", "WAITING_HELP",
           "ENDED_HELP", "SAID_FOR"]

#: seconds the footer shows the run's answer to a key (or why a key sent nothing), then the help again
SAID_FOR = 6.0


class LiveView:
    """Redraws ``state`` in place on a terminal (rich.live, alternate screen) until stopped;
    ``footer`` (or a callable making it from the state) is the last line, ``title`` the header's first words.
    With ``summary`` (``bmtree watch``), what the alternate screen took with it is printed once it
    has ended: the result with its whole reason, calls a run that is gone may have left running,
    other runs on the master (``bmtree run`` prints its own report instead)."""

    def __init__(self, state: WatchState, console: Any = None, footer: Union[str, Callable[[WatchState], str]] = "",
                 refresh: float = 0.2, title: str = "bmtree watch", summary: bool = False):
        from rich.console import Console

        self.state = state
        self.console = console or Console()
        self.footer = footer
        self.title = title
        self.refresh = refresh
        self.summary = summary
        self.message = ""  # the answer to a key, or why it sent nothing (for SAID_FOR s, on the same run)
        self.typing: Optional[str] = None  # the command being typed after ':' (shown until Enter or Esc)
        self._since: Any = None  # the run's last control record when the message came
        self._said_at = 0.0  # when the message came (monotonic)
        self._said_run = ""  # the run shown then
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    def answered(self, message: str, run: Optional[str] = None, since: Any = False) -> None:
        """The run's answer to a key (or why a key sent nothing), for the footer: for :data:`SAID_FOR`
        seconds, and only while the same run is shown (then the help comes back). ``run``: the run the
        key was for; its answer is not said once another one is shown. ``since``: the run's last control
        record when the key was sent (the records of the command, and of a breakpoint that paused the run
        again at once, may come before its answer)."""
        with self.state.lock:
            if run is not None and run != self.state.run:
                return
            self._since = since if since is not False else self.state.control[-1] if self.state.control else None
            self.message = message
            self._said_at = time.monotonic()
            self._said_run = self.state.run

    def said(self) -> str:
        """The message the footer shows now: none once :data:`SAID_FOR` seconds have passed, or another
        run is shown (a reply to a key is about the run it was sent to)."""
        with self.state.lock:
            if self.message and (time.monotonic() - self._said_at > SAID_FOR or self.state.run != self._said_run):
                self.message = ""
            return self.message

    def foot(self) -> str:
        """The footer: the command being typed; else an answer replaces the help for a few seconds; an
        answer that the run's state has overtaken says so (``ok: resumed`` when a breakpoint paused it
        again at once)."""
        if self.typing is not None:
            return ":" + self.typing
        help_ = self.footer(self.state) if callable(self.footer) else self.footer
        message = self.said()
        foot = message or help_
        if message.startswith("ok: resumed") and self.state.paused:
            with self.state.lock:
                records = self.state.control
                after = next((k + 1 for k in range(len(records) - 1, -1, -1) if records[k] is self._since), 0)
                held = [c for c in records[after:] if c.get("paused")]  # came after the key was sent
            if held:
                foot += "; paused again: %s" % held[-1].get("answer")
        return foot.strip()

    def _frame(self, anchor: List[float]) -> Any:
        size = self.console.size
        answer = self.said() if self.typing is None else ""
        return render(self.state, size.width, size.height, self.foot(), now_since(self.state, anchor), self.title,
                      footer_wrap=bool(answer))

    def _loop(self) -> None:
        from rich.live import Live

        anchor: List[float] = []
        with Live(self._frame(anchor), console=self.console, screen=True, auto_refresh=False,
                  redirect_stdout=False, redirect_stderr=False) as live:
            while not self._stop.wait(self.refresh):
                live.update(self._frame(anchor), refresh=True)

    def start(self) -> LiveView:
        self._thread = threading.Thread(target=self._loop, name="bmtree-live-view", daemon=True)
        self._thread.start()
        return self

    def stop(self, final: bool = True) -> None:
        """Leave the alternate screen; with ``final`` print the last view once (it stays in the
        scrollback) and, with ``summary``, the lines of :func:`summary_lines` (wrapped, never cut)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        if final:
            self.console.print(self.final())

    def final(self) -> Any:
        """What stays on the normal screen: the last view, and the summary below it."""
        from rich.console import Group
        from rich.text import Text

        size = self.console.size
        frame = render(self.state, size.width, max(24, size.height) - 1, "", title=self.title,
                       result="none" if self.summary else "full")
        if not self.summary:
            return frame
        status = str((self.state.end or {}).get("status"))
        style = {"SUCCESS": "green", "FAILURE": "bold red", "UNFINISHED": "bold red"}.get(status, "")
        lines = [Text(line, style=style if k == 0 else "") for k, line in enumerate(summary_lines(self.state))]
        return Group(frame, *lines)


KEYS_HELP = ("q quit  p pause/resume  s step  : command (stop, break NODE, clear NODE, force NODE SUCCESS, "
             "set KEY VALUE)")
NO_CONTROL_HELP = "q quit  (this run takes no commands: it was started without --control)"
WAITING_HELP = "q quit  (waiting for a run: the steering keys come with a run started with --control)"
ENDED_HELP = "q quit  (the run has ended: it takes no more commands)"


def keys_help(state: WatchState) -> str:
    """The footer: the steering keys only while the run shown takes them (its ``tree`` record said so
    and it has not ended); else why there are none."""
    with state.lock:
        if state.steerable:
            return KEYS_HELP
        if not state.nodes:
            return WAITING_HELP
        return NO_CONTROL_HELP if state.tree.get("control") is False else ENDED_HELP


class Keys:
    """The watch's keys: p, s, q, and ``:`` for a typed command; answers go to the view's footer.
    ``to()``: the ROS node of the run shown, named in each command (another run on the master
    leaves it alone)."""

    def __init__(self, view: LiveView, client: Any, stop: threading.Event,
                 to: Callable[[], Optional[str]] = lambda: None):
        self.view, self.client, self.stop, self.to = view, client, stop, to
        self.line: Optional[str] = None

    def _send(self, cmd: Dict[str, Any]) -> None:
        why = self.view.state.no_steering()
        if why:  # nothing would take it: said here, nothing is sent
            self.view.answered("not sent: %s" % why)
            return
        node = self.to()
        if node:
            cmd = dict(cmd, to=node)
        with self.view.state.lock:
            run = self.view.state.run
            since = self.view.state.control[-1] if self.view.state.control else None

        def go() -> None:
            reply = self.client.send(cmd, 10.0)
            self.view.answered(("ok: " if reply.get("ok") else "refused: ") + str(reply.get("answer")), run, since)
        threading.Thread(target=go, daemon=True).start()

    def press(self, ch: str) -> None:
        from coordinator.control import parse_command

        if self.line is not None:
            if ch in ("\r", "\n"):
                words, self.line = self.line.split(), None
                self.view.typing = None
                try:
                    self._send(parse_command(words))
                except ValueError as exc:
                    self.view.answered("refused: %s" % exc)
            elif ch == "\x1b":
                self.line = self.view.typing = None
            elif ch in ("\x7f", "\b"):
                self.line = self.view.typing = self.line[:-1]
            elif ch.isprintable():
                self.line += ch
                self.view.typing = self.line
            return
        if ch in ("q", "Q"):
            self.stop.set()
        elif ch in ("p", "s", ":") and self.view.state.no_steering():  # said at once, nothing sent
            self.view.answered("'%s' not sent: %s" % (ch, self.view.state.no_steering()))
        elif ch == "p":
            self._send({"command": "resume" if self.view.state.paused else "pause"})
        elif ch == "s":
            self._send({"command": "step"})
        elif ch == ":":
            self.line = self.view.typing = ""


def key_reader(handler: Callable[[str], None], stop: threading.Event) -> Optional[threading.Thread]:
    """Single keys from a terminal's stdin (cbreak mode), given to ``handler``; None without a terminal."""
    if not sys.stdin.isatty():
        return None
    import select
    import termios
    import tty

    fd = sys.stdin.fileno()
    old = termios.tcgetattr(fd)

    def loop() -> None:
        tty.setcbreak(fd)
        try:
            while not stop.is_set():
                ready, _, _ = select.select([fd], [], [], 0.2)
                if ready:
                    ch = os.read(fd, 1).decode("utf-8", "replace")
                    handler(ch)
        finally:
            termios.tcsetattr(fd, termios.TCSADRAIN, old)

    t = threading.Thread(target=loop, name="bmtree-keys", daemon=True)
    t.start()
    return t
