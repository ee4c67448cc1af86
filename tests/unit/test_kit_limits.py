"""``TreeTest.run`` ends every run, with the tick limits of ``bmtree test`` (coordinator/testing/limits.py)."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from coordinator.testing import TickLimitError, TreeTest, scenario
from coordinator.testing.limits import DEFAULT_MAX_TICKS, DEFAULT_MAX_TICKS_PER_INSTANT, TickGuard
from tests.conftest import ROOT

# Accepted by bmtree check (a repeat of instant nodes is no reactive composite), and against mocks that
# answer at once it never lets the simulated clock move: before the limit, TreeTest.run spun for ever.
LIVELOCK = """format: 1
name: livelock
root:
  repeat: 1000000000
  child:
    sequence:
      - set: {x: a}
      - %s
"""


def _tree(tmp_path, leaf="call: speech.say\n        inputs: {text: hi}"):
    path = tmp_path / "livelock.yaml"
    path.write_text(LIVELOCK % leaf)
    return str(path)


def test_a_livelock_fails_the_test_with_the_limit_by_default(tmp_path):
    path = _tree(tmp_path)
    script = textwrap.dedent("""
        from coordinator.testing import TickLimitError, TreeTest
        try:
            TreeTest(%r).run()
        except TickLimitError as exc:
            print("RAISED", exc.hit)
            print("CALLS", len(exc.run.calls()), exc.run.failed)
            print("MESSAGE", exc)
    """ % path)
    # a subprocess with a timeout: without the limit this run never ends
    out = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == ("RAISED stopped after %d ticks at simulated time 0 s without the clock advancing "
                        "(max_ticks_per_instant): a livelock, loops restarting at once? Raise it with "
                        "t.run(max_ticks_per_instant=...) if this tree needs more" % DEFAULT_MAX_TICKS_PER_INSTANT)
    assert lines[1].startswith("CALLS ") and lines[1].endswith(" True") and int(lines[1].split()[1]) > 1000
    assert lines[2].startswith("MESSAGE %s: stopped after %d ticks" % (path, DEFAULT_MAX_TICKS_PER_INSTANT))
    assert lines[2].endswith("(it was stopped while 'repeat x1000000000' was running (between runs: run 5000 of "
                             "1000000000 succeeded))")


def test_the_limits_are_arguments_of_run_and_fail_whatever_the_test_expects(tmp_path):
    t = TreeTest(_tree(tmp_path))
    with pytest.raises(TickLimitError, match=r"stopped after 50 ticks at simulated time 0 s .*"
                                             r"t\.run\(max_ticks_per_instant=\.\.\.\)") as caught:
        t.run(max_ticks_per_instant=50)
    assert isinstance(caught.value, AssertionError)   # a failed test, not an error of the kit
    assert caught.value.run.result.ticks == 50 and caught.value.run.failed
    creeping = TreeTest(_tree(tmp_path, leaf="wait: 0.001"))
    with pytest.raises(TickLimitError, match=r"stopped after 300 ticks \(max_ticks\) at simulated time .*; raise it "
                                             r"with t\.run\(max_ticks=\.\.\.\) if this tree needs more"):
        creeping.run(max_ticks=300)


def test_a_run_that_ends_within_the_limits_is_untouched(tmp_path):
    path = tmp_path / "t.yaml"   # 9000 ticks at one instant, then the end
    path.write_text("format: 1\nroot:\n  for_each: %s\n  as: i\n  child:\n"
                    "    repeat: 90\n    child:\n      set: {y: $i}\n" % list(range(100)))
    t = TreeTest(str(path))
    run = t.run()
    assert run.succeeded and run.blackboard["y"] == 99 and run.result.ticks < DEFAULT_MAX_TICKS_PER_INSTANT
    with pytest.raises(TickLimitError):
        t.run(max_ticks=1000)
    # the test's own stop_when still stops the run, as a FAILURE with its reason
    run = t.run(stop_when=lambda: "enough")
    assert run.failed and run.reason.startswith("enough while ")


def test_the_scenarios_use_the_kits_limits():
    assert scenario.TickGuard is TickGuard
    assert (scenario.DEFAULT_MAX_TICKS, scenario.DEFAULT_MAX_TICKS_PER_INSTANT) == (
        DEFAULT_MAX_TICKS, DEFAULT_MAX_TICKS_PER_INSTANT)
    assert "TickGuard(" not in open(scenario.__file__).read()   # no guard of their own: TreeTest.run's


def test_a_cleanup_that_livelocks_is_cut_short_by_the_limit_too(tmp_path):
    """The cleanup's own time limit is on the simulated clock, which a livelock never moves."""
    path = tmp_path / "cleanup_livelock.yaml"
    path.write_text(LIVELOCK.replace("name: livelock\nroot:", "name: cleanup_livelock\nroot:\n  set: {y: b}\ncleanup:")
                    % "call: speech.say\n        inputs: {text: hi}")
    script = textwrap.dedent("""
        from coordinator.testing import TickLimitError, TreeTest
        try:
            TreeTest(%r).run(max_ticks_per_instant=300)
        except TickLimitError as exc:
            print("RAISED", exc.run.result.status, exc.run.result.cleanup_status, exc.run.result.cleanup_reason)
    """ % str(path))
    out = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.startswith("RAISED Status.SUCCESS Status.FAILURE stopped after 300 ticks at simulated time 0 s "
                                 "without the clock advancing"), out.stdout + out.stderr
