"""``bmtree replay``'s text lists the module events the run received (the report after a replay,
``--at``, ``--failure``): for a tree that waits for an event (``wait_event``), which events came and
when is half of why it failed — one with other params, one that came before the node started
waiting. Bounded to the last ones, and nothing at all for a run that received none (no ROS master)."""
from __future__ import annotations

import io
import json
import types

from coordinator.replay import Replay, _report, cmd_replay
from coordinator.runlog import RunLogWriter, read_log
from coordinator.runstream import RunStream
from coordinator.testing import TreeTest
from coordinator.testing.mocks import succeed
from modules.search import default_definitions

VOICE = {
    "Basic Module": "voice", "Brief Description": "asks, and hears what people say", "Hardware Required": [],
    "Functions": [{"Name": "ask", "Exec-condition": "", "Description": "say a question",
                   "Input-params": [{"Name": "question", "Data-type": "std_msgs/String", "Description": "what"}],
                   "Output-params": []}],
    "Events": [{"Name": "heard", "Description": "speech was heard",
                "Event-params": [{"Name": "text", "Data-type": "std_msgs/String", "Description": "what was heard"}]}],
}

ASK = """format: 1
name: ask_door
root:
  sequence:
    name: ask and wait
    children:
      - call: voice.ask
        name: ask
        inputs: {question: "open the door?"}
      - wait_event: voice.heard
        name: wait for yes
        where: text == "yes"
%s"""


def recorded(tmp_path, script, timeout="        timeout: 2\n", **run):
    """ASK run on mocks (``voice.ask`` answers after 0.5 s, so the wait starts then) scripted by
    ``script(mocks)``, with a run log: the log's path."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    (tmp_path / "voice.json").write_text(json.dumps(VOICE))
    (tmp_path / "ask.yaml").write_text(ASK % timeout)
    t = TreeTest(str(tmp_path / "ask.yaml"), definitions=default_definitions([str(tmp_path / "voice.json")]))
    t.mocks["voice.ask"].script(succeed(delay=0.5))
    script(t.mocks)
    log = str(tmp_path / "run.jsonl")
    t.run(observers=[RunStream([RunLogWriter(log, fsync=False)])], **run)
    return log


def replayed(capsys, log, **kw):
    args = dict(run=log, dir=None, at=None, step=False, failure=False, scenario=None, speed=None)
    args.update(kw)
    assert cmd_replay(types.SimpleNamespace(**args)) == 0
    return capsys.readouterr().out


def heard_too_early_and_wrong(mocks):
    """"yes" before the wait started; then "yeah" (other params), "\x9b2J" (a terminal's control), a long one."""
    mocks.event(0.2, "voice.heard", text="yes")
    mocks.event(1.0, "voice.heard", text="yeah")
    mocks.event(1.25, "voice.heard", text="\x9b2J")
    mocks.event(1.5, "voice.heard", text="x" * 80)


ROWS = ['  +  0.200s  voice.heard                {"text":"yes"}',
        '  +  1.000s  voice.heard                {"text":"yeah"}',
        '  +  1.250s  voice.heard                {"text":"\\x9b2J"}',
        '  +  1.500s  voice.heard                {"text":"%s…' % ("x" * 50)]


def test_the_report_after_a_replay_lists_the_events_in_time_order_in_the_columns_of_the_calls(tmp_path, capsys):
    log = recorded(tmp_path, heard_too_early_and_wrong)
    out = replayed(capsys, log)
    assert "reason: wait for yes: no voice.heard where text == \"yes\" within 2s (3 skipped)" in out, out
    report = out.split("\ncalls:\n", 1)[1].splitlines()
    assert report[:6] == ["  +  0.000s  voice.ask                  succeeded     0.500s", "events:"] + ROWS, out
    assert "\x9b" not in out and "earlier event" not in out, out  # escaped; all four shown
    direct = io.StringIO()   # escaped by the report itself, not only by the terminal's stream
    replay = Replay(read_log(log))
    while replay.next() is not None:
        pass
    _report(replay, direct)
    assert ROWS[2] in direct.getvalue().splitlines() and "\x9b" not in direct.getvalue()


def test_at_a_moment_the_events_received_by_then(tmp_path, capsys):
    out = replayed(capsys, recorded(tmp_path, heard_too_early_and_wrong), at=1.2)
    lines = out.splitlines()
    assert lines[lines.index("calls in flight: none"):] == ["calls in flight: none", "events received by 1.200s:"] + \
        ROWS[:2], out
    out = replayed(capsys, recorded(tmp_path, heard_too_early_and_wrong), at=0.1)   # none yet: no heading
    assert "events received" not in out and out.splitlines()[-1].endswith("ask.yaml:7)"), out  # the call: last


def test_failure_of_a_wait_event_shows_the_events_before_it(tmp_path, capsys):
    out = replayed(capsys, recorded(tmp_path, heard_too_early_and_wrong), failure=True)
    assert "the failure that ended the run, at 2.500s: 'wait for yes'" in out, out
    lines = out.splitlines()
    assert lines[lines.index("calls in flight: none"):] == ["calls in flight: none", "events received before the failure:"] + \
        ROWS, out


def test_failure_of_a_run_stopped_while_it_waited_shows_the_events_before_the_stop(tmp_path, capsys):
    log = recorded(tmp_path, heard_too_early_and_wrong, timeout="", max_duration=3.0)  # waits with no limit
    out = replayed(capsys, log, failure=True)
    assert "no leaf's failure ended this run: stopped after 3" in out, out
    # the state at its last tick (the wait began), the events until the stop: the wait skipped three
    assert "the state at its last tick before it was stopped, at 0.500s:" in out, out
    assert out.splitlines()[-6:] == ["calls in flight: none", "events received before it was stopped:"] + ROWS, out


def test_a_run_without_events_prints_no_events_heading_where_one_with_events_does(tmp_path, capsys):
    with_events = recorded(tmp_path / "with", heard_too_early_and_wrong)
    without = recorded(tmp_path / "without", lambda mocks: None)
    for kw, head in (({}, "events:"), ({"at": 2.0}, "events received by 2.000s:"),
                     ({"failure": True}, "events received before the failure:")):
        assert head in replayed(capsys, with_events, **kw).splitlines()
        out = replayed(capsys, without, **kw)
        assert not [line for line in out.splitlines() if line.startswith("events") or "voice.heard  " in line], out
        assert out.endswith("calls in flight: none\n" if kw else "  +  0.000s  voice.ask                  succeeded     "
                            "0.500s\n"), out


def many(mocks):
    """25 events, none the one awaited: ``n1`` at 0.1 s … ``n25`` at 2.5 s (the wait gives up at 3.5 s)."""
    for k in range(1, 26):
        mocks.event(0.1 * k, "voice.heard", text="n%d" % k)


def _rows(out, head):
    lines = out.splitlines()
    return lines[lines.index(head) + 1:]


def test_the_events_shown_are_the_last_ones_with_how_many_earlier_were_left_out(tmp_path, capsys):
    log = recorded(tmp_path, many, timeout="        timeout: 3\n")
    rows = _rows(replayed(capsys, log), "events:")
    assert rows[0] == "  … 5 earlier events left out" and len(rows) == 21, rows
    assert [json.loads(r.split(None, 3)[3])["text"] for r in rows[1:]] == ["n%d" % k for k in range(6, 26)], rows
    assert rows[1] == '  +  0.600s  voice.heard                {"text":"n6"}', rows

    rows = _rows(replayed(capsys, log, at=1.25), "events received by 1.250s:")
    assert rows[0] == "  … 2 earlier events left out" and len(rows) == 11, rows
    assert [json.loads(r.split(None, 3)[3])["text"] for r in rows[1:]] == ["n%d" % k for k in range(3, 13)], rows

    rows = _rows(replayed(capsys, log, failure=True), "events received before the failure:")
    assert rows[0] == "  … 15 earlier events left out" and len(rows) == 11, rows
    assert [json.loads(r.split(None, 3)[3])["text"] for r in rows[1:]] == ["n%d" % k for k in range(16, 26)], rows

    rows = _rows(replayed(capsys, log, at=2.05), "events received by 2.050s:")
    assert rows[0] == "  … 10 earlier events left out" and rows[-1].endswith('{"text":"n20"}'), rows
    one = recorded(tmp_path / "one", lambda m: [m.event(0.1 * k, "voice.heard", text="n%d" % k) for k in range(1, 22)])
    assert _rows(replayed(capsys, one), "events:")[0] == "  … 1 earlier event left out"
