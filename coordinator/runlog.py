"""Run logs: the run stream as JSON lines, one file per run, durable at every tick.

Why JSON lines and not SQLite: a run is written once, in order, and read whole; an
append-only text file costs one ``write`` per tick, and a crash (``kill -9``, power
loss) can only cut the last line, which the reader drops. The records are the run
stream's own, byte for byte, so a log and a ``rosbag`` of ``/bmtree/run/*`` say the
same thing and ``jq``/``grep`` read both. Writing happens in a thread: the ticking
thread only hands over the tick's lines; the thread writes them and ``fsync``s.
"""
from __future__ import annotations

import os
import queue
import re
import stat
import threading
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Sequence, Set, Tuple

from comm.errors import InvalidInput
from comm.nodelife import registering
from coordinator.runrecords import MAX_RECORD_BYTES, parse_record, record_problem, version_problem
from coordinator.runstream import RunStream, Sink

__all__ = ["RunFiles", "plan_run_files", "RunLogWriter", "RunLog", "RunLogError", "RunSummary", "default_runs_dir", "read_log", "list_runs",
           "new_log_path", "prune", "empty_file", "last_alive", "writer_alive", "DEFAULT_KEEP", "MAX_LOG_BYTES",
           "MAX_RECORD_BYTES", "max_log_bytes", "definition_files"]

DEFAULT_KEEP = 50
MAX_LOG_BYTES = 64 << 20          # a log larger than this is refused, not read (read, it takes ~10 times that)
MAX_WARNINGS = 10                 # lines skipped that a reader names (then how many more)
_SUFFIX = ".jsonl"
HEARTBEAT = 1.0  # seconds: a quiet run's log is touched this often, so a killed run's length is known
_NAME = re.compile(r"^\d{8}-\d{6}-[A-Za-z0-9_.-]+\.jsonl$")
_SIM = re.compile(r"^\d{8}-\d{6}-[A-Za-z0-9_.-]+\.sim$")
_SNIFF_BYTES = 4096  # of a .jsonl not named as bmtree names its logs: a tree record says "tree" in them


class RunLogError(InvalidInput, ValueError):
    """A file that is not a run log (``path:line: message``), or a bad recording option: exit code 2."""


def default_runs_dir() -> str:
    """``$ROS_HOME/bmtree/runs`` (``~/.ros`` when ROS_HOME is not set, as ROS does)."""
    home = os.environ.get("ROS_HOME") or os.path.join(os.path.expanduser("~"), ".ros")
    return os.path.join(home, "bmtree", "runs")


def new_log_path(directory: str, run_id: str, tree_name: str) -> str:
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", tree_name)[:60] or "tree"
    return os.path.join(directory, "%s-%s%s" % (run_id, safe, _SUFFIX))


def _logs_in(directory: str) -> Tuple[List[str], List[str]]:
    """The regular files of ``directory`` that may be run logs: (those named as bmtree names its own,
    ``<start>-<id>-<tree>.jsonl``; the other ``.jsonl`` files, such as ``--record`` ones)."""
    try:
        names = sorted(n for n in os.listdir(directory) if n.endswith(_SUFFIX))
    except OSError:
        return [], []
    paths = [os.path.join(directory, n) for n in names]
    paths = [p for p in paths if os.path.isfile(p)]  # a FIFO of that name would hang the reader
    named = [p for p in paths if _NAME.match(os.path.basename(p))]
    return named, [p for p in paths if not _NAME.match(os.path.basename(p))]


def _looks_like_log(path: str) -> bool:
    """True if the first bytes of ``path`` may start a run log's ``tree`` record (a JSON object naming
    ``"tree"``), so that a folder's other ``.jsonl`` files (data of the user's) cost one short read each."""
    with open(path, "rb") as fh:
        start = fh.read(_SNIFF_BYTES)
    return start.lstrip().startswith(b"{") and b'"tree"' in start


def prune(directory: str, keep: int) -> List[str]:
    """Delete all but the newest ``keep`` runs of ``directory``: a run's log and its ``.sim``
    directory (a simulated robot's store and logs) go together; the names sort by start time. Only
    the files bmtree named itself count and go: a ``--record`` log of another name there, which
    ``bmtree runs`` lists too, is the user's and is never deleted."""
    import shutil

    try:
        names = [n for n in os.listdir(directory) if _NAME.match(n) or _SIM.match(n)]
    except OSError:
        return []
    runs = sorted({os.path.splitext(n)[0] for n in names})
    old = set(runs[:max(0, len(runs) - keep)])
    gone = []
    for name in sorted(names):
        if os.path.splitext(name)[0] not in old:
            continue
        path = os.path.join(directory, name)
        if name.endswith(_SUFFIX):
            try:
                os.remove(path)
            except OSError:
                continue
        else:
            shutil.rmtree(path, ignore_errors=True)
        gone.append(path)
    return gone


class RunFiles:
    """Where one ``bmtree run`` keeps its log and, with ``--sim``, the simulated robot's files."""

    def __init__(self, run_id: str, log_path: Optional[str], sim_dir: str):
        self.run_id = run_id
        self.log_path = log_path
        self.sim_dir = sim_dir
        self.writer: Optional[RunLogWriter] = None

    def recorder(self, sinks: List[Sink], inputs: Dict[str, Any], max_duration: Optional[float],
                 world: Optional[str], control: bool = False, modules: Sequence[str] = ()) -> Any:
        """The run-stream observer writing to ``sinks`` and, unless ``--no-record``, the log.
        ``control``: the run takes control commands (``--control``), so viewers offer them.
        ``modules``: the definition files the run was given (``--modules``, ``--module``), so that
        a scenario made from its log can say how to test it; the ``tree`` record also has, as
        ``definitions``, the file of every definition the run had that is not the simulated robot's
        (:func:`definition_files`: the packages' exports and ``$BMTREE_MODULE_PATH``'s too)."""
        meta: Dict[str, Any] = {"inputs": inputs, "max_duration": max_duration, "control": control}
        if modules:
            meta["modules"] = [os.path.abspath(m) for m in modules]
        if world is not None or os.path.isdir(self.sim_dir):
            meta["sim"] = {"world": os.path.abspath(world) if world else None, "dir": self.sim_dir}
        all_sinks = list(sinks)
        if self.log_path is not None:
            self.writer = RunLogWriter(self.log_path)
            all_sinks.append(self.writer)
        return _RecordingStream(all_sinks, meta, self.run_id, linger=True)   # closed by bmtree run after the cancels

    def report(self, say: Any) -> None:
        if self.writer is not None:
            say("run log: %s%s" % (self.log_path, "  (NOT complete: %s)" % self.writer.error
                                   if self.writer.error else ""))
        if os.path.isdir(self.sim_dir):
            say("simulated robot's Blackboard store and module logs: %s" % self.sim_dir)


def definition_files(definitions: Mapping[str, Any]) -> Dict[str, str]:
    """Module name -> the absolute path of the file its definition was read from, for the definitions
    that are not the simulated robot's (a ROS package's export, ``$BMTREE_MODULE_PATH``, ``--modules``):
    what a scenario made from the run's log names in its ``modules:``. A definition the run had only from
    the live graph (a module's announcement) is in no file, and not here."""
    from modules.search import SIM_DIR

    sim = os.path.join(os.path.realpath(SIM_DIR), "")
    out: Dict[str, str] = {}
    for name, d in sorted(definitions.items()):
        source = getattr(d, "source", None)
        if getattr(d, "name", None) != name or not isinstance(source, str) or not os.path.isfile(source):
            continue
        if not os.path.realpath(source).startswith(sim):
            out[name] = os.path.abspath(source)
    return out


class _RecordingStream(RunStream):
    """``bmtree run``'s run stream: its ``tree`` record also says where the run's definitions came from
    (``definitions``: :func:`definition_files` of the run's), known when the run starts."""

    def on_start(self, tree: Any, root: Any, ctx: Any) -> None:
        files = definition_files(getattr(ctx, "definitions", None) or {})
        if files:
            self.meta["definitions"] = files
        super().on_start(tree, root, ctx)


def plan_run_files(tree_path: str, record: Optional[str], no_record: bool, keep: Optional[int]) -> RunFiles:
    """Name this run's files and apply the retention (newest ``keep`` runs, this one included)."""
    import time
    import uuid

    if keep is None:
        env = os.environ.get("BMTREE_KEEP_RUNS", "")
        try:
            keep = int(env) if env else DEFAULT_KEEP
        except ValueError:
            raise RunLogError("BMTREE_KEEP_RUNS must be a whole number, got %r" % env)
    if keep < 1:
        raise RunLogError("--keep-runs must be at least 1, got %d" % keep)
    directory = default_runs_dir()
    run_id = "%s-%s" % (time.strftime("%Y%m%d-%H%M%S"), uuid.uuid4().hex[:6])
    name = os.path.splitext(os.path.basename(tree_path))[0]
    default = new_log_path(directory, run_id, name)
    log_path = None if no_record else (os.path.abspath(record) if record else default)
    if record and not no_record and os.path.lexists(log_path) and not empty_file(log_path):
        if not _is_run_log(log_path):  # the tree itself, or any file of the user's: never appended to
            raise RunLogError("--record %s: the file exists and is not a bmtree run log; bmtree does not write "
                              "into it (choose a new name)" % record)
        os.remove(log_path)  # an earlier run's log: this run's replaces it
    prune(directory, keep - 1)
    return RunFiles(run_id, log_path, default[:-len(_SUFFIX)] + ".sim")


def empty_file(path: str) -> bool:
    """A regular file with nothing in it (``mktemp``'s): nothing of the user's to lose."""
    return os.path.isfile(path) and os.path.getsize(path) == 0


def _is_run_log(path: str) -> bool:
    """True if ``path`` is a regular file whose first record is a run log's ``tree`` record."""
    if not os.path.isfile(path):
        return False
    try:
        return _head(path) is not None
    except (OSError, ValueError):
        return False


def _head(path: str) -> Dict[str, Any]:
    """The first record of ``path``, a run log's ``tree`` record (RunLogError why not; OSError)."""
    with open(path, "rb") as fh:
        raw = fh.readline(MAX_RECORD_BYTES + 1)
    rec, problem = _parse(raw)
    return _header(path, 1, rec, problem or "")


class RunLogWriter(Sink):
    """Appends records to ``path``; each tick's lines are written and fsync'd by a writer thread."""

    def __init__(self, path: str, fsync: bool = True):
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        self.path = path
        self.fsync = fsync
        self._fh = open(path, "ab")
        self._batch: List[str] = []
        self._queue: queue.Queue = queue.Queue()
        self._thread = threading.Thread(target=self._write_loop, name="bmtree-runlog", daemon=True)
        self._thread.start()
        self.error: Optional[OSError] = None

    def write(self, channel: str, text: str) -> None:
        self._batch.append(text)

    def flush(self) -> None:
        if self._batch:
            with registering():   # a Ctrl-C between the put and the reset would write the batch twice
                self._queue.put(self._batch)
                self._batch = []

    def _write_loop(self) -> None:
        while True:
            try:
                batch = self._queue.get(timeout=HEARTBEAT)
            except queue.Empty:  # a quiet run: the file's time still says it was alive (a killed run's length)
                try:
                    os.utime(self.path)
                except OSError:
                    pass
                continue
            if batch is None:
                return
            lines = [batch]
            while True:  # take whatever else is waiting: one write and one fsync for all of it
                try:
                    more = self._queue.get_nowait()
                except queue.Empty:
                    break
                if more is None:
                    self._queue.put(None)
                    break
                lines.append(more)
            data = "".join(t + "\n" for b in lines for t in b).encode("utf-8")
            try:
                self._fh.write(data)
                self._fh.flush()
                if self.fsync:
                    os.fsync(self._fh.fileno())
            except OSError as exc:  # a full disk must not stop the robot
                self.error = exc

    def close(self) -> None:
        self.flush()
        self._queue.put(None)
        self._thread.join()
        self._fh.close()


@dataclass
class RunLog:
    """One run read back: its records in order, and whether the end is missing."""

    path: str
    records: List[Dict[str, Any]]
    truncated: bool = False        # the last line was cut (the process died while writing)
    mtime: Optional[float] = None  # when the file was last written or touched (the writer's heartbeat)
    warnings: List[str] = field(default_factory=list)  # the first lines skipped, each ``path:line: why``
    skipped: int = 0               # how many lines were skipped (not records this bmtree can use)

    def skip(self, why: str) -> None:
        self.skipped += 1
        if len(self.warnings) < MAX_WARNINGS:
            self.warnings.append(why)

    def warning_lines(self) -> List[str]:
        """What a reader tells on stderr of the lines it skipped (at most MAX_WARNINGS of them)."""
        out = ["warning: %s (line skipped)" % w for w in self.warnings]
        if self.skipped > len(self.warnings):
            out.append("warning: %s: %d more lines skipped" % (self.path, self.skipped - len(self.warnings)))
        return out

    @property
    def tree(self) -> Dict[str, Any]:
        return self.records[0]

    @property
    def end(self) -> Optional[Dict[str, Any]]:
        """The end record: the last one but for the notices that came after it (answers to its cancels)."""
        for rec in reversed(self.records):
            if rec.get("type") != "notice":
                return rec if rec.get("type") == "end" else None
        return None

    def of_type(self, kind: str) -> List[Dict[str, Any]]:
        return [r for r in self.records if r.get("type") == kind]

    @property
    def last_alive(self) -> float:
        """Seconds from the start the run lived: its end's, or for a killed run (no end record) the
        later of its last record and the last heartbeat touch of the file, as ``bmtree runs`` lists it."""
        end = self.end
        if end is not None:
            return float(end.get("duration") or end.get("t") or 0.0)
        return last_alive(float(self.tree.get("started") or 0.0), self.records[-1].get("t"), self.mtime)


def last_alive(started: float, last_t: Any, mtime: Optional[float]) -> float:
    """How long a run without an end record lived: its last record's time, or later if the writer
    touched the file after it (it does every second while the run is quiet)."""
    t = float(last_t) if isinstance(last_t, (int, float)) else 0.0
    if started and mtime is not None:
        t = max(t, mtime - started)
    return t


def max_log_bytes() -> int:
    """How large a run log may be to be read: MAX_LOG_BYTES, or ``$BMTREE_MAX_LOG_MB`` megabytes."""
    from coordinator.cliutil import count, from_env
    from coordinator.errors import UsageError

    try:
        mb = from_env("BMTREE_MAX_LOG_MB", count(what="megabytes a run log may have to be read"))
    except UsageError as exc:
        raise RunLogError(str(exc))
    return mb << 20 if mb else MAX_LOG_BYTES


def _parse(raw: bytes) -> Tuple[Optional[Dict[str, Any]], str]:
    """One line decoded: (the record, '') or (None, why not): :func:`coordinator.runrecords.parse_record`."""
    if len(raw) > MAX_RECORD_BYTES:
        return None, "a line of %d bytes, more than the %d a record may have" % (len(raw), MAX_RECORD_BYTES)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        return None, "not UTF-8 text (byte %d of the line)" % (exc.start + 1)
    return parse_record(text)


def _header(path: str, number: int, rec: Optional[Dict[str, Any]], problem: str) -> Dict[str, Any]:
    """The first record, a run log's ``tree`` record (RunLogError saying why the log cannot be read)."""
    if rec is None:
        raise RunLogError("%s:%d: %s" % (path, number, problem))
    if not isinstance(rec, dict) or rec.get("type") != "tree":
        raise RunLogError("%s:%d: not a bmtree run log (it must start with a 'tree' record)" % (path, number))
    said = version_problem(rec.get("v"))
    if said is not None:
        raise RunLogError("%s:%d: this run log was %s" % (path, number, said))
    problem = record_problem(rec) or ""
    if problem:
        raise RunLogError("%s:%d: %s" % (path, number, problem))
    return rec


def read_log(path: str) -> RunLog:
    """Read a run log: a cut last line is dropped, and every other line that is not a record this bmtree
    can use is skipped, said in ``warnings`` (``path:line: why``). RunLogError when the log cannot be
    read at all: not a regular file, larger than :func:`max_log_bytes`, its ``tree`` record unusable."""
    limit = max_log_bytes()
    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode):
            raise RunLogError("%s: not a run log (not a regular file)" % path)
        with open(path, "rb") as fh:
            data = fh.read(limit + 1) if st.st_size <= limit else b""
    except OSError as exc:
        raise RunLogError("%s: %s" % (path, exc.strerror or exc))
    if st.st_size > limit or len(data) > limit:  # (or it grew past the limit while read)
        raise RunLogError("%s: %s is larger than the %d MB a run log may have to be read (BMTREE_MAX_LOG_MB=N "
                          "reads up to N MB)" % (path, "%.1f MB" % (max(st.st_size, len(data)) / 2.0 ** 20), limit >> 20))
    lines = data.split(b"\n")
    del data
    log = RunLog(path, [], mtime=st.st_mtime)
    ids: Set[int] = set()
    for number, raw in enumerate(lines, 1):
        if not raw.strip():
            continue
        rec, problem = _parse(raw)
        if rec is None and number == len(lines):   # no newline after it: the writer was killed in the middle of it
            log.truncated = True
            break
        if not log.records:
            log.records.append(_header(path, number, rec, problem))
            ids = {n["id"] for n in log.records[0]["nodes"]}
            continue
        problem = problem or record_problem(rec, ids) or ""
        if not problem and rec.get("type") == "tree":
            problem = "a second tree record (a run log holds one run)"
        if problem:
            log.skip("%s:%d: %s" % (path, number, problem))
        else:
            log.records.append(rec)
    if not log.records:
        raise RunLogError("%s:1: not a bmtree run log (it must start with a 'tree' record)" % path)
    return log


@dataclass
class RunSummary:
    path: str
    name: str
    started: float
    duration: Optional[float]
    status: str
    reason: str
    extra: Dict[str, Any] = field(default_factory=dict)


def _tail_record(path: str, ids: Set[int]) -> Tuple[Optional[Dict[str, Any]], str]:
    """The last complete record of ``path`` (a cut last line is dropped), or its end record when only notices
    follow it (the answers to the run's cancels, which came after its end), and, when it cannot be used, why
    (``path:line: why``; the log reads as one without an end)."""
    with open(path, "rb") as fh:
        fh.seek(0, os.SEEK_END)
        size = fh.tell()
        fh.seek(max(0, size - 65536))
        tail = fh.read().split(b"\n")
    last: Optional[Dict[str, Any]] = None   # the last record, when only notices are in the tail
    for back, raw in enumerate(reversed(tail)):
        if back == len(tail) - 1 and size > 65536:
            break      # the start of the block, in the middle of a line
        rec, problem = _parse(raw)
        if rec is None and (back == 0 or not raw.strip()):
            continue   # the cut last line, or the empty one after the last newline
        problem = problem or record_problem(rec, ids) or ""
        if problem:
            return None, "%s:%d: %s" % (path, _line_count(path) + 1 - back, problem)
        if rec.get("type") == "notice":   # after the end record, the answers to its cancels: the end is before
            last = last or rec
            continue
        return (rec if rec.get("type") == "end" else last or rec), ""
    return last, ""


def _line_count(path: str) -> int:
    """The lines of ``path`` (its newlines), read in blocks."""
    n = 0
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            n += block.count(b"\n")
    return n


def writer_alive(head: Dict[str, Any]) -> bool:
    """True if the process that writes the run log whose ``tree`` record is ``head`` still runs: the
    ``pid`` it recorded is alive here, a bmtree process (its command line says so) started no later than
    the run (not another process that got the pid since). Without ``/proc`` (not Linux) it is not known:
    False, as for a log without a pid."""
    pid, started = head.get("pid"), head.get("started")
    if not isinstance(pid, int) or isinstance(pid, bool) or pid <= 0 or not isinstance(started, (int, float)):
        return False
    try:
        with open("/proc/%d/cmdline" % pid, "rb") as fh:
            cmdline = fh.read().replace(b"\0", b" ")
        with open("/proc/%d/stat" % pid, "rb") as fh:
            fields = fh.read().rsplit(b")", 1)[1].split()
        with open("/proc/stat", "rb") as fh:
            boot = next(float(line.split()[1]) for line in fh if line.startswith(b"btime "))
        since = boot + int(fields[19]) / os.sysconf("SC_CLK_TCK")   # field 22, starttime (ticks after boot)
    except (OSError, ValueError, IndexError, StopIteration):
        return False
    if fields[0] == b"Z":   # exited, not yet reaped: not writing
        return False
    return (b"bmtree" in cmdline or b"coordinator" in cmdline) and since <= started + 2.0  # btime is whole seconds


def _run_head(path: str, named: bool) -> Optional[Dict[str, Any]]:
    """The ``tree`` record of ``path``; None for a file not named as bmtree names its logs whose first
    line is no ``tree`` record (not a run log: another ``.jsonl`` of the user's). RunLogError for a run
    log whose first record cannot be used (or one named as bmtree's that is no run log); OSError."""
    if not named:
        if not _looks_like_log(path):
            return None
        with open(path, "rb") as fh:
            rec, _problem = _parse(fh.readline(MAX_RECORD_BYTES + 1))
        if not isinstance(rec, dict) or rec.get("type") != "tree":
            return None
    return _head(path)


def list_runs(directory: str, problems: Optional[List[str]] = None) -> List[RunSummary]:
    """Every run log of ``directory``, oldest first (by the start its ``tree`` record says): the ones bmtree
    named (``<start>-<id>-<tree>.jsonl``) and any other ``.jsonl`` whose first record is a run's (``--record
    FILE``; only its first line is read to know, at most a record's size). A log bmtree cannot read is left
    out, and why is added to ``problems`` (``path:line: why``); the other ``.jsonl`` files that are no run
    logs are counted there in one line. A log whose last record cannot be used is listed as one without
    an end, and why is added too."""
    out = []
    named, others = _logs_in(directory)
    not_logs = 0
    for path, ours in [(p, True) for p in named] + [(p, False) for p in others]:
        try:
            head = _run_head(path, ours)
            if head is None:
                not_logs += 1
                continue
            tail, problem = _tail_record(path, {n["id"] for n in head["nodes"]})
            mtime = os.path.getmtime(path)
        except (OSError, ValueError) as exc:  # not a log bmtree wrote, or damaged: `bmtree replay FILE` says more
            if problems is not None:
                problems.append("%s (not listed)" % (exc if isinstance(exc, RunLogError) else "%s: %s" % (path, exc)))
            continue
        if problem and problems is not None:
            problems.append(problem)
        end = tail if tail is not None and tail.get("type") == "end" else None
        last_t = tail.get("t") if tail is not None else None
        duration = end.get("t") if end else last_t
        started = float(head.get("started") or 0.0)
        if end is None and started:  # killed: it lived until its log was last written or touched
            duration = last_alive(started, duration, mtime)
        running = end is None and writer_alive(head)
        out.append(RunSummary(
            path=path, name=str(head.get("name", "?")), started=started,
            duration=float(duration) if duration is not None else None,
            status=str(end.get("status")) if end else "RUNNING" if running else "UNFINISHED",
            reason=str(end.get("reason") or "") if end else
            "still running (pid %s)" % head.get("pid") if running else
            "the log ends without an end record (killed?)",
            extra={"run": head.get("run")} if isinstance(head.get("run"), str) else {}))
    if not_logs and problems is not None:
        problems.append("%s: %s (not listed)" % (directory, "1 other .jsonl file is not a run log (its first line is no "
                        "run's 'tree' record)" if not_logs == 1 else "%d other .jsonl files are not run logs (their first "
                        "lines are no run's 'tree' record)" % not_logs))
    out.sort(key=lambda r: (r.started, os.path.basename(r.path)))
    return out
