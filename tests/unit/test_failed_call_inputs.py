"""The summary shows the inputs of the call the failure names; when the failure is a call that could not
be built (no call was made), no other call's: the C++ audit's for_each over [0.2, "slow"] printed the
failure's inputs note on the row of the earlier call, which had succeeded, in bmtree run and replay."""
from __future__ import annotations

import io

from coordinator.replay import Replay
from coordinator.replay import _report as replay_summary
from coordinator.runlog import read_log
from coordinator.runner import summary_lines
from coordinator.testing.mocks import succeed
from tests.unit.test_recording import recorded


def _replayed(log: str) -> Replay:
    replay = Replay(read_log(log))
    while replay.next(None) is not None:
        pass
    return replay


TREE = """format: 1
name: waits
inputs:
  durations: {default: [0.2, "slow"]}
root:
  sequence:
    - set: {ds: "$(durations)"}
    - for_each: $ds
      as: d
      child:
        call: speech.listen
        inputs: {seconds: $d}
"""   # (through an expression: check does not follow the list's elements there, so the call is refused when built)


def test_a_call_that_could_not_be_built_shows_no_other_calls_inputs(sim_defs, tmp_path):
    path = tmp_path / "waits.yaml"
    path.write_text(TREE)
    log, run = recorded(str(path), sim_defs, tmp_path, lambda m: m["speech.listen"].script(succeed(text="ok")))
    assert run.failed and "cannot build the call: input 'seconds' takes a number" in run.reason, run.reason
    assert run.result.failed_call is None
    rows = [line for line in summary_lines(run.result, "waits") if line.startswith("  +")]
    assert len(rows) == 1 and "succeeded" in rows[0] and "inputs" not in rows[0], rows
    out = io.StringIO()
    replay_summary(_replayed(log), out)
    rows = [line for line in out.getvalue().splitlines() if line.startswith("  +")]
    assert len(rows) == 1 and "succeeded" in rows[0] and "inputs" not in rows[0], out.getvalue()


def test_the_failed_call_still_shows_its_inputs(sim_defs, tmp_path):
    path = tmp_path / "waits.yaml"
    path.write_text(TREE.replace('[0.2, "slow"]', "[0.2, 0.5]"))
    log, run = recorded(str(path), sim_defs, tmp_path,
                        lambda m: m["speech.listen"].script(succeed(text="ok"), succeed(success=False)))
    assert run.failed
    rows = [line for line in summary_lines(run.result, "waits") if line.startswith("  +")]
    assert 'inputs {"seconds":0.5}' in rows[1] and "inputs" not in rows[0], rows
    out = io.StringIO()
    replay_summary(_replayed(log), out)
    rows = [line for line in out.getvalue().splitlines() if line.startswith("  +")]
    assert 'inputs {"seconds":0.5}' in rows[1] and "inputs" not in rows[0], out.getvalue()
