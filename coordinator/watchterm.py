"""The terminal side of ``bmtree watch`` and ``bmtree run``: the live view redrawn in place on the
alternate screen, what stays on the normal screen once it ends, and the steering keys."""
from __future__ import annotations

import os
import sys
import threading
from typing import Any, Callable, Dict, List, Optional, Union

from coordinator.watchstate import WatchState
from coordinator.watchtext import summary_lines
from coordinator.watchview import now_since, render

__all__ = ["LiveView", "Keys", "key_reader", "keys_help", "KEYS_HELP", "NO_CONTROL_HELP"]


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
        self.message = ""
        self._since: Any = None  # the run's last control record when the message came
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    def answered(self, message: str) -> None:
        """The run's answer to a key, for the footer (the help comes back with the next key)."""
        with self.state.lock:
            self._since = self.state.control[-1] if self.state.control else None
            self.message = message

    def foot(self) -> str:
        """The footer: an answer replaces the help until the next key; an answer that the run's
        state has overtaken says so (``ok: resumed`` when a breakpoint paused it again at once)."""
        help_ = self.footer(self.state) if callable(self.footer) else self.footer
        foot = self.message or help_
        if self.message.startswith("ok: resumed") and self.state.paused:
            with self.state.lock:
                records = self.state.control
                after = next((k + 1 for k in range(len(records) - 1, -1, -1) if records[k] is self._since), 0)
                held = [c for c in records[after:] if c.get("paused")]  # came after the answer
            if held:
                foot += "; paused again: %s" % held[-1].get("answer")
        return foot.strip()

    def _frame(self, anchor: List[float]) -> Any:
        size = self.console.size
        return render(self.state, size.width, size.height, self.foot(), now_since(self.state, anchor), self.title,
                      footer_wrap=bool(self.message))

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


def keys_help(state: WatchState) -> str:
    """The footer: the steering keys only for a run that takes them."""
    return KEYS_HELP if state.steerable else NO_CONTROL_HELP


class Keys:
    """The watch's keys: p, s, q, and ``:`` for a typed command; answers go to the view's footer.
    ``to()``: the ROS node of the run shown, named in each command (another run on the master
    leaves it alone)."""

    def __init__(self, view: LiveView, client: Any, stop: threading.Event,
                 to: Callable[[], Optional[str]] = lambda: None):
        self.view, self.client, self.stop, self.to = view, client, stop, to
        self.line: Optional[str] = None

    def _send(self, cmd: Dict[str, Any]) -> None:
        node = self.to()
        if node:
            cmd = dict(cmd, to=node)

        def go() -> None:
            reply = self.client.send(cmd, 10.0)
            self.view.answered(("ok: " if reply.get("ok") else "refused: ") + str(reply.get("answer")))
        threading.Thread(target=go, daemon=True).start()

    def press(self, ch: str) -> None:
        from coordinator.control import parse_command

        if self.line is not None:
            if ch in ("\r", "\n"):
                words, self.line = self.line.split(), None
                try:
                    self._send(parse_command(words))
                except ValueError as exc:
                    self.view.message = "refused: %s" % exc
            elif ch == "\x1b":
                self.line, self.view.message = None, ""
            elif ch in ("\x7f", "\b"):
                self.line = self.line[:-1]
                self.view.message = ":" + self.line
            elif ch.isprintable():
                self.line += ch
                self.view.message = ":" + self.line
            return
        if ch in ("q", "Q"):
            self.stop.set()
        elif ch == "p":
            self._send({"command": "resume" if self.view.state.paused else "pause"})
        elif ch == "s":
            self._send({"command": "step"})
        elif ch == ":":
            self.line = ""
            self.view.message = ":"


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
