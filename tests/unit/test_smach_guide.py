"""docs/smach.md, "Porting a SMACH state machine to bmtree": every YAML block of the guide is loaded with the
real loader (and checked with ``bmtree check --strict``), the recipes run against the mocked modules with
the behaviour the guide says, its scenario file passes ``bmtree test``, its pytest example passes, its module
class answers a cancel as the guide says, and the messages it quotes are the ones bmtree gives.

A block starts with the name of the file it is (``# bring_cup.yaml``), or ``# NAME (nodes of a sequence)``
for a piece of a tree's root sequence, which is run wrapped in ``format: 1 / root: sequence:``."""
from __future__ import annotations

import importlib.util
import os
import re
import shlex
import shutil
import textwrap
import threading

import pytest

from coordinator.cli import main as bmtree
from coordinator.language import load_tree
from coordinator.testing import fail, hang, reject, succeed
from modules.definition import load_definitions
from modules.sim import SIM_DIR
from tests.conftest import DATA, ROOT

DOC = os.path.join(ROOT, "docs", "smach.md")
ARM = os.path.join(DATA, "smach_guide", "arm.json")
DEFS = load_definitions([SIM_DIR, ARM])
FRAGMENT = "(nodes of a sequence)"

with open(DOC, encoding="utf-8") as _fh:
    TEXT = _fh.read()

# every named block of the guide, and what it is
KINDS = {
    "bring_cup.yaml": "tree", "ask.yaml": "tree", "take_order.yaml": "tree", "keep_answer": "fragment",
    "learn_name.yaml": "tree", "retry_then_ask": "fragment", "look_around": "fragment",
    "search_rooms.yaml": "tree", "serve_guests.yaml": "tree", "five_rounds": "fragment",
    "lead_guest.yaml": "tree", "lead_and_chat": "fragment", "first_sighting": "fragment",
    "all_to_the_end": "fragment", "wait_for_guest.yaml": "tree", "offer_charge.yaml": "tree",
    "grasp_cup.yaml": "tree", "arm.py": "module", "in_time": "fragment", "test_bring_cup.py": "pytest",
    "grasp_cup.scenarios.yaml": "scenarios", "arm_standin.yaml": "script",
}
TREES = sorted(name for name, kind in KINDS.items() if kind in ("tree", "fragment"))
P = {"x": 4.2, "y": 0.4, "z": 0.5}


def doc_blocks():
    """[(language, first line, text)] of the guide's fenced blocks, each dedented (those in list items too)."""
    found = re.findall(r"^( *)```(\w+)\n(.*?)^\1```[ \t]*$", TEXT, re.M | re.S)
    return [(lang, textwrap.dedent(body).split("\n", 1)[0], textwrap.dedent(body)) for _, lang, body in found]


def named_blocks():
    blocks = {}
    for lang, first, body in doc_blocks():
        match = re.match(r"# (\S+)( \(nodes of a sequence\))?$", first)
        if lang in ("yaml", "python") and match and (lang == "yaml" or match.group(1).endswith(".py")):
            assert match.group(1) not in blocks, "two blocks named %s" % match.group(1)
            blocks[match.group(1)] = body
    return blocks


BLOCKS = named_blocks()


def slug(heading: str) -> str:
    """GitHub's anchor of a heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def write_guide(folder) -> None:
    """Every file block of the guide into ``folder`` (a fragment as a one-file tree NAME.yaml), with arm.json."""
    shutil.copy(ARM, str(folder / "arm.json"))
    for name, body in BLOCKS.items():
        if KINDS.get(name) == "fragment":
            body = "format: 1\nroot:\n  sequence:\n" + textwrap.indent(body, "    ")
            name += ".yaml"
        (folder / name).write_text(body)


@pytest.fixture
def guide(tmp_path, bmtree_tree):
    """``guide(name)`` -> a TreeTest of the guide's tree or fragment ``name`` (files written to tmp_path)."""
    write_guide(tmp_path)

    def make(name, **kwargs):
        path = tmp_path / (name if name.endswith(".yaml") else name + ".yaml")
        return bmtree_tree(str(path), definitions=DEFS, **kwargs)

    return make


def quoted(text: str) -> str:
    """``text`` as the guide quotes it (its lines joined), asserted to be there."""
    assert text in " ".join(TEXT.split()), "docs/smach.md no longer quotes %r" % text
    return text


# the blocks themselves --------------------------------------------------------------------------------------
def test_every_block_is_named_and_known():
    yaml_firsts = [first for lang, first, _ in doc_blocks() if lang == "yaml"]
    assert all(first.startswith("# ") for first in yaml_firsts), yaml_firsts   # every YAML block is named
    assert set(BLOCKS) == set(KINDS), set(BLOCKS) ^ set(KINDS)
    for name, kind in KINDS.items():
        marked = ("# %s %s" % (name, FRAGMENT)) in TEXT
        assert marked == (kind == "fragment"), name


def test_the_smach_snippets_are_python():
    """The SMACH side of each recipe is valid Python (not run: no SMACH here)."""
    snippets = [body for lang, _, body in doc_blocks() if lang == "python"]
    assert len(snippets) >= 10
    for body in snippets:
        compile(body, "docs/smach.md", "exec")


@pytest.mark.parametrize("name", TREES)
def test_every_tree_and_fragment_loads_and_checks_without_warnings(tmp_path, capsys, name):
    write_guide(tmp_path)
    path = str(tmp_path / (name if name.endswith(".yaml") else name + ".yaml"))
    load_tree(path, DEFS)
    assert bmtree(["check", "--strict", "--modules", ARM, path]) == 0, capsys.readouterr()


def test_the_links_lead_to_headings():
    def anchors(path):
        with open(path, encoding="utf-8") as fh:
            return {slug(line.lstrip("#")) for line in fh if line.startswith("#")}

    own = anchors(DOC)
    links = re.findall(r"\]\(([^)]*)\)", TEXT)
    assert links
    for link in links:
        target, _, anchor = link.partition("#")
        path = os.path.normpath(os.path.join(ROOT, "docs", target)) if target else DOC
        assert os.path.exists(path), link
        if anchor:
            assert anchor in (anchors(path) if target else own), link
    table = TEXT.split("\n## ", 1)[0]
    for section in range(1, 11):
        assert "(#%d-" % section in table, section


# 1. StateMachine and transitions ----------------------------------------------------------------------------
def test_bring_cup_routes_the_find_on_its_status(guide):
    t = guide("bring_cup.yaml")
    t.mocks["navigation.go_to"].script(succeed(room="living_room"))
    t.mocks["vision.find_object"].script(succeed(position=P))
    t.mocks["navigation.approach"].script(succeed(position=P))
    run = t.run()
    assert run.succeeded, run.reason
    assert run.calls("navigation.approach")[0].inputs["target"] == P      # the succeeded case read the output
    assert run.said() == []

    t = guide("bring_cup.yaml")
    t.mocks["navigation.go_to"].script(succeed(room="living_room"))
    t.mocks["vision.find_object"].script(succeed(success=False))           # failed: SAY_NO_CUP -> aborted
    run = t.run()
    assert run.failed and run.reason == "fail: no cup in sight", run.reason
    assert run.said() == ["I cannot see the cup."] and run.calls("navigation.approach") == []

    t = guide("bring_cup.yaml")
    t.mocks["navigation.go_to"].script(succeed(room="living_room"))
    t.mocks["vision.find_object"].script(reject("busy"))                    # default
    run = t.run()
    assert run.failed and run.reason == "fail: vision.find_object: rejected", run.reason


def test_bring_cup_says_why_the_room_is_unreachable(guide):
    t = guide("bring_cup.yaml")
    t.mocks["navigation.go_to"].script(hang())
    run = t.run()
    assert run.failed and run.duration == pytest.approx(60.0)
    assert run.said() == ["I cannot get to the living room: no answer within 60s"]
    assert run.calls("vision.find_object") == []


def test_only_the_succeeded_case_may_read_the_outputs(tmp_path):
    write_guide(tmp_path)
    text = (tmp_path / "bring_cup.yaml").read_text().replace('"I cannot see the cup."', '"No cup at {cup_at}."')
    (tmp_path / "bad.yaml").write_text(text)
    with pytest.raises(Exception) as info:
        load_tree(str(tmp_path / "bad.yaml"), DEFS)
    assert "reads 'cup_at', which is not written on every path before this node" in str(info.value)


# 2. userdata and remapping ----------------------------------------------------------------------------------
def test_take_order_remaps_the_subtrees_keys(guide):
    t = guide("take_order.yaml", inputs={"guest": "Bob"})
    t.mocks["speech.listen"].script(succeed(text="yes please"), succeed(text="no"))
    run = t.run()
    assert run.succeeded, run.reason
    assert run.said() == ["Bob, would you like a coffee?", "And a tea?",
                         "Bob: coffee yes please, tea no (2 questions)."]
    assert run.blackboard["answer"] == "no" and run.blackboard["question"] == "And a tea?"   # not hidden


def test_outputs_to_the_same_key_says_the_replacement_is_meant(guide, tmp_path, capsys, monkeypatch):
    t = guide("keep_answer")
    t.mocks["speech.listen"].script(succeed(text="black, please"))
    run = t.run()
    assert run.succeeded and run.said() == ["Coffee?", "You said: black, please"]
    without = tmp_path / "without.yaml"
    without.write_text((tmp_path / "keep_answer.yaml").read_text().replace("  outputs: {answer: answer}", ""))
    capsys.readouterr()
    monkeypatch.chdir(tmp_path)
    assert bmtree(["check", "--strict", "without.yaml"]) == 2
    assert quoted("ask.yaml writes 'answer' (ask.yaml:11), replacing the caller's 'answer'") in capsys.readouterr().err


# 3. back-edges -----------------------------------------------------------------------------------------------
def test_learn_name_says_hello_again_and_asks_again(guide):
    t = guide("learn_name.yaml")
    t.mocks["speech.listen"].script(fail("nothing heard"), succeed(text=""), succeed(text="I am Anna"),
                                    succeed(text="no"), succeed(text="my name is Ana"), succeed(text="Yes!"))
    run = t.run()
    assert run.succeeded, run.reason
    assert run.said() == ["Hello! What is your name?", "Sorry, what is your name?", "Sorry, what is your name?",
                         "Is your name Anna?", "Hello! What is your name?", "Is your name Ana?",
                         "Nice to meet you, Ana."]


def test_learn_name_gives_up_after_three_rounds(guide):
    t = guide("learn_name.yaml")
    t.mocks["speech.listen"].script(succeed(text="Bob"), succeed(text="nope"))
    run = t.run()
    assert run.failed
    assert quoted("reached its maximum of 3 runs while confirmed was still false (confirmed = false)") in run.reason
    assert run.said().count("Hello! What is your name?") == 3


def test_retry_then_ask_for_help(guide):
    t = guide("retry_then_ask")
    t.mocks["navigation.go_to"].script(fail("door closed"), fail("door closed"), fail("door closed"),
                                       succeed(room="kitchen"))
    run = t.run()
    assert run.succeeded, run.reason
    assert [c.status for c in run.calls("navigation.go_to")] == ["failed"] * 3 + ["succeeded"]
    assert run.said() == ["I cannot get to the kitchen. Could someone open the door?"]
    assert run.duration == pytest.approx(2 + 2 + 10)   # the delays between attempts, then the wait

    t = guide("retry_then_ask")
    t.mocks["navigation.go_to"].script(fail("door closed"), succeed(room="kitchen"))
    run = t.run()
    assert run.succeeded and run.said() == [] and len(run.calls("navigation.go_to")) == 2


def test_look_around_moves_before_each_new_attempt(guide):
    t = guide("look_around")
    t.mocks["navigation.go_to"].script(succeed(room="living_room"))
    t.mocks["vision.find_object"].script(succeed(success=False), succeed(success=False), succeed(position=P))
    run = t.run()
    assert run.succeeded, run.reason
    assert [c.inputs["place"] for c in run.calls("navigation.go_to")] == ["sofa", "fridge"]
    assert run.blackboard["cup_at"] == P and run.blackboard["attempt"] == 2


# 4. Iterator -------------------------------------------------------------------------------------------------
def test_search_rooms_breaks_at_the_first_room_with_the_apple(guide):
    t = guide("search_rooms.yaml")
    t.mocks["navigation.go_to"].script(fail("blocked"), succeed(room="kitchen"))
    t.mocks["vision.find_object"].script(succeed(position=P))
    run = t.run()
    assert run.succeeded, run.reason
    assert run.said() == ["Room 1 of 3: the living_room.", "Room 2 of 3: the kitchen."]
    assert [c.inputs["place"] for c in run.calls("navigation.go_to")] == ["living_room", "kitchen"]


def test_search_rooms_exhausted_takes_the_selectors_fallback(guide):
    t = guide("search_rooms.yaml", inputs={"rooms": ["kitchen", "bedroom"]})
    t.mocks["navigation.go_to"].script(succeed(room="kitchen"))
    t.mocks["vision.find_object"].script(succeed(success=False))
    run = t.run()
    assert run.failed and run.reason == "fail: no apple", run.reason
    assert run.said()[-1] == "I looked in 2 rooms: no apple."


def test_serve_guests_continues_past_a_missing_guest_and_breaks_when_the_tray_is_empty(guide):
    t = guide("serve_guests.yaml")
    t.mocks["vision.find_person"].script(succeed(success=False), succeed(person="Bob", position=P),
                                         succeed(person="Carl", position=P))
    t.mocks["navigation.approach"].script(succeed(position=P))
    run = t.run()
    assert run.succeeded, run.reason
    assert run.said() == ["Here is your drink, Bob.", "Here is your drink, Carl.", "I served 2 of 3 guests."]

    t = guide("serve_guests.yaml")
    t.mocks["vision.find_person"].script(succeed(person="someone", position=P))
    t.mocks["navigation.approach"].script(succeed(position=P))
    run = t.run()
    assert run.succeeded, run.reason
    assert run.said() == ["Here is your drink, Ana.", "Here is your drink, Bob.", "I served 2 of 3 guests."]
    assert len(run.calls("vision.find_person")) == 2   # Carl: the loop broke before him


def test_five_rounds_is_a_range_that_goes_on_past_failures(guide):
    t = guide("five_rounds")
    t.mocks["vision.find_object"].script(succeed(position=P), fail("camera covered"), succeed(success=False),
                                         succeed(position=P))
    run = t.run()
    assert run.succeeded, run.reason
    assert run.said() == ["Round %d." % n for n in range(1, 6)]
    assert run.blackboard["i"] == 4


# 5. Concurrence ----------------------------------------------------------------------------------------------
def test_lead_guest_ends_when_the_guest_is_lost(guide):
    t = guide("lead_guest.yaml")
    t.mocks["navigation.go_to"].succeed(delay=10, room="living_room")
    t.mocks.event(3.0, "vision.lostPerson", person="Bob")     # not the guest: skipped
    t.mocks.event(4.0, "vision.lostPerson", person="Ana")
    run = t.run()
    assert run.succeeded, run.reason
    assert run.said() == ["Ana, where are you? Please come back."]
    assert [(c.status, c.ended) for c in run.calls("navigation.go_to")] == [("halted", 4.0)]


def test_lead_guest_arrives_or_fails_with_the_drive(guide):
    t = guide("lead_guest.yaml")
    t.mocks["navigation.go_to"].succeed(delay=10, room="living_room")
    t.mocks.event(3.0, "vision.lostPerson", person="Bob")
    run = t.run()
    assert run.succeeded and run.said() == ["Here is the living room, Ana."] and run.duration == pytest.approx(10)

    t = guide("lead_guest.yaml")
    t.mocks["navigation.go_to"].fail("blocked", delay=5)
    run = t.run()
    assert run.failed and run.reason == "arrived: navigation.go_to failed: blocked" and run.said() == []


def test_lead_and_chat_ends_with_the_lead(guide):
    t = guide("lead_and_chat")
    t.mocks["navigation.go_to"].succeed(delay=12, room="dining_room")
    run = t.run()
    assert run.succeeded, run.reason
    assert run.duration == pytest.approx(12.0)
    assert run.said() == ["This way, please."] * 3        # at 0, 5 and 10 s; halted at 12

    t = guide("lead_and_chat")
    t.mocks["navigation.go_to"].succeed(delay=12, room="dining_room")
    t.mocks["speech.say"].script(fail("speaker unplugged"))
    run = t.run()
    assert run.succeeded and run.duration == pytest.approx(12.0)   # the chat's failure does not count


def test_first_sighting_takes_the_event_after_the_look_failed(guide):
    t = guide("first_sighting")
    t.mocks["vision.find_person"].script(succeed(success=False, delay=2))
    seen = {"x": 1.0, "y": 2.0, "z": 0.0}
    t.mocks.event(5.0, "vision.personSeen", person="Ana", position=seen)
    t.mocks["navigation.approach"].script(succeed(position=seen))
    run = t.run()
    assert run.succeeded, run.reason
    assert run.calls("navigation.approach")[0].inputs["target"] == seen and run.duration == pytest.approx(5.0)

    t = guide("first_sighting")
    t.mocks["vision.find_person"].script(succeed(success=False, delay=2))
    run = t.run()
    assert run.failed and run.duration == pytest.approx(20.0)      # both failed: the event's timeout


def test_all_to_the_end_lets_every_child_end_then_decides(guide):
    t = guide("all_to_the_end")
    t.mocks["navigation.go_to"].script(fail("blocked", delay=1))
    t.mocks["speech.say"].script(succeed(delay=3))
    run = t.run()
    assert run.failed and run.duration == pytest.approx(3.0)
    assert [c.status for c in run.calls("speech.say")] == ["succeeded"]      # not halted by the failure
    assert 'went == "succeeded" is false' in run.reason, run.reason

    t = guide("all_to_the_end")
    t.mocks["navigation.go_to"].script(succeed(room="kitchen", delay=1))
    t.mocks["speech.say"].script(fail("speaker unplugged", delay=3))
    run = t.run()
    assert run.succeeded, run.reason


# 6. MonitorState --------------------------------------------------------------------------------------------
def test_wait_for_guest_takes_the_first_matching_event(guide):
    t = guide("wait_for_guest.yaml")
    t.mocks.event(2.0, "vision.personSeen", person="Bob", position={"x": 1.0, "y": 0.0, "z": 0.0})
    t.mocks.event(3.0, "vision.personSeen", person="Ana", position={"x": -1.0, "y": 0.0, "z": 0.0})
    t.mocks.event(5.0, "vision.personSeen", person="Ana", position={"x": 2.0, "y": 1.0, "z": 0.0})
    t.mocks["navigation.approach"].script(succeed(position=P))
    run = t.run()
    assert run.succeeded, run.reason
    assert run.calls("navigation.approach")[0].inputs["target"] == {"x": 2.0, "y": 1.0, "z": 0.0}
    assert run.said() == ["Welcome, Ana!"] and run.duration == pytest.approx(5.0)


def test_wait_for_guest_times_out_saying_how_many_were_skipped(guide):
    t = guide("wait_for_guest.yaml", inputs={"guest": "Ana"})
    t.mocks.event(2.0, "vision.personSeen", person="Bob", position={"x": 1.0, "y": 0.0, "z": 0.0})
    run = t.run()
    assert run.failed and run.duration == pytest.approx(30.0)
    assert quoted("no vision.personSeen where person == guest and position.x > 0 within 30s (1 skipped)") in run.reason


# 7. CBState ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("pct, heard, ok, calls, spoken", [
    (42.5678, "Yes, please!", True, ["navigation.go_to", "battery.charge"], "42.6"),
    (55.0, "No.", True, [], "55"),
    (42.5, "I don't know", True, ["speech.say"], "42.5"),        # "no" in words(...): false
    (50.0, "yesterday", True, ["speech.say"], "50"),             # "yes" in words(...): false
    (12.04, "no thanks", False, [], "12"),
])
def test_offer_charge_parses_the_answer_and_checks_the_level(guide, pct, heard, ok, calls, spoken):
    t = guide("offer_charge.yaml")
    t.mocks["battery.level"].succeed(percentage=pct)
    t.mocks["speech.listen"].succeed(text=heard)
    t.mocks["navigation.go_to"].succeed(room="entrance")
    t.mocks["battery.charge"].succeed(percentage=100.0)
    run = t.run()
    assert run.succeeded is ok, run.reason
    assert run.said()[0] == "My battery is at %s percent. Shall I go and charge?" % spoken
    assert [c.target for c in run.calls()][3:] == calls
    if calls == ["speech.say"]:
        assert run.said()[-1] == 'Sorry, I did not understand "%s".' % heard
    if not ok:
        assert quoted("pct >= 20 is false (pct = 12.04)") in run.reason


# 8. preemption and clean-up ------------------------------------------------------------------------------------
def grasp(guide):
    t = guide("grasp_cup.yaml")
    t.mocks["navigation.go_to"].succeed(room="living_room")
    t.mocks["vision.find_object"].succeed(position=P)
    t.mocks["navigation.approach"].succeed(position=P)
    return t


def test_grasp_cup_cleanup_after_success_failure_and_stop(guide):
    t = grasp(guide)
    t.mocks["arm.grasp"].succeed(delay=3)
    run = t.run()
    assert run.succeeded and run.ended == "succeeded" and run.cleanup_status == "SUCCESS"
    assert run.said() == ["I have the cup."] and run.calls("arm.reset") == []

    t = grasp(guide)
    t.mocks["arm.grasp"].fail("slipped")
    run = t.run()
    assert run.failed and run.reason == "take the cup: arm.grasp failed: slipped", run.reason
    assert [c.target for c in run.cleanup_calls()] == ["arm.reset", "speech.say"]
    assert run.statuses("take the cup") == ["RUNNING", "FAILURE"] and run.cleanup_status == "SUCCESS"
    assert run.said() == ["Sorry, I could not take the cup (failed)."]

    t = grasp(guide)
    t.mocks["arm.grasp"].hang()
    run = t.run(max_duration=5)                       # a stop from outside: Ctrl-C, --max-duration
    assert run.failed and run.ended == "stopped" and run.cleanup_status == "SUCCESS"
    assert [c.status for c in run.calls("arm.grasp")] == ["halted"]
    assert run.said() == ["Sorry, I could not take the cup (stopped)."]


def test_grasp_cup_timeouts(guide):
    t = grasp(guide)
    t.mocks["arm.grasp"].hang()
    run = t.run()
    assert [(c.status, c.error) for c in run.calls("arm.grasp")] == [("timeout", "no answer within 20s")]
    assert run.duration == pytest.approx(20.0)

    t = grasp(guide)
    t.mocks["navigation.approach"].succeed(delay=30, position=P)
    t.mocks["arm.grasp"].hang()
    run = t.run()
    assert [c.status for c in run.calls("arm.grasp")] == ["halted"]        # the decorator fired at 40 s
    assert run.duration == pytest.approx(40.0)
    assert "timed out after 40s while 'arm.grasp' was running" in run.reason, run.reason


def test_the_arm_module_stops_when_its_call_is_cancelled(tmp_path):
    from comm import CancelRequest
    from tests.unit.test_runtime import Served

    (tmp_path / "guide_arm.py").write_text(BLOCKS["arm.py"])
    spec = importlib.util.spec_from_file_location("guide_arm", str(tmp_path / "guide_arm.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)

    class Driven(module.Arm):
        done = False
        stopped = False

        def __init__(self):
            super().__init__()
            self.running = threading.Event()

        def _start_grasp(self, name, target):
            self.started = (name, target.x)
            self.running.set()

        def _grasp_done(self):
            return self.done

        def _stop_arm(self):
            self.stopped = True

    arm = Driven()
    served = Served(DEFS["arm"], arm)
    call = served.call("grasp", object="cup", target=P)
    assert arm.running.wait(5)                    # cancelled while it runs, not before it started
    served.server.handle_cancel(CancelRequest(call, "arm", "grasp").encode())
    assert served.result(call).status == "cancelled"
    assert arm.stopped and arm.started == ("cup", 4.2)

    arm = Driven()
    arm.done = True
    served = Served(DEFS["arm"], arm)
    result = served.result(served.call("grasp", object="cup", target=P))
    assert result.status == "succeeded" and result.values["success"].data is True and not arm.stopped


# 9. timeouts --------------------------------------------------------------------------------------------------
def test_in_time_routes_a_call_timeout_and_the_group_times_out(guide):
    t = guide("in_time")
    t.mocks["navigation.go_to"].script(hang())
    run = t.run()
    assert run.succeeded, run.reason
    assert [(c.status, c.error) for c in run.calls("navigation.go_to")] == [("timeout", "no answer within 60s")]
    assert run.said() == ["The kitchen is too far, I stay here."] and run.duration == pytest.approx(60.0)

    t = guide("in_time")
    t.mocks["navigation.go_to"].script(succeed(room="kitchen", delay=50))
    t.mocks["vision.find_object"].script(hang())
    run = t.run()
    assert run.failed and run.duration == pytest.approx(90.0)
    assert [c.status for c in run.calls("vision.find_object")] == ["halted"]
    assert quoted("timed out after 90s while 'vision.find_object' was running") in run.reason, run.reason

    t = guide("in_time")
    t.mocks["navigation.go_to"].script(fail("blocked"))
    run = t.run()
    assert run.failed and run.reason == "fail: navigation failed", run.reason


def test_a_call_without_timeout_waits_the_call_timeout(tmp_path, bmtree_tree):
    path = tmp_path / "t.yaml"
    path.write_text("format: 1\nroot:\n  call: navigation.go_to\n  inputs: {place: kitchen}\n")
    t = bmtree_tree(str(path), definitions=DEFS)
    t.mocks["navigation.go_to"].script(hang())
    run = t.run()
    assert run.failed and run.duration == pytest.approx(30.0) and "no answer within 30s" in run.reason
    assert quoted("`--call-timeout`, 30 s by default")


# 10. testing --------------------------------------------------------------------------------------------------
def test_the_pytest_example_passes(tmp_path, monkeypatch, bmtree_tree):
    write_guide(tmp_path)
    monkeypatch.chdir(tmp_path)
    spec = importlib.util.spec_from_file_location("guide_test_bring_cup", str(tmp_path / "test_bring_cup.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    tests = [getattr(module, name) for name in dir(module) if name.startswith("test_")]
    assert len(tests) == 2
    for test in tests:
        test(bmtree_tree)


def test_the_scenario_file_passes(tmp_path, capsys):
    write_guide(tmp_path)
    assert bmtree(["test", str(tmp_path / "grasp_cup.scenarios.yaml")]) == 0, capsys.readouterr()
    assert capsys.readouterr().out.splitlines()[-1] == "2 passed, 0 failed"


def test_the_scenario_file_fails_when_the_tree_changes(tmp_path, capsys):
    """It tests something: without the reset in the cleanup, both scenarios fail."""
    write_guide(tmp_path)
    tree = tmp_path / "grasp_cup.yaml"
    tree.write_text(tree.read_text().replace("      - call: arm.reset\n", ""))
    assert bmtree(["test", str(tmp_path / "grasp_cup.scenarios.yaml")]) == 1
    assert capsys.readouterr().out.splitlines()[-1] == "0 passed, 2 failed"


def test_the_stand_in_script_fits_the_arm(tmp_path):
    from coordinator.testing.mocknode import load_script

    write_guide(tmp_path)
    definition, _ = load_script(str(tmp_path / "arm_standin.yaml"), DEFS)
    assert definition.name == "arm"


def test_the_shell_commands_that_need_no_robot_run(tmp_path, monkeypatch, capsys):
    write_guide(tmp_path)
    monkeypatch.chdir(tmp_path)
    shell = re.findall(r"```sh\n(.*?)```", TEXT, re.S)
    lines = [line.split("#", 1)[0].strip() for block in shell for line in block.splitlines()]
    offline = [shlex.split(line)[1:] for line in lines if line.startswith(("bmtree check", "bmtree render"))]
    assert [args[0] for args in offline] == ["check", "render"]
    for args in offline:
        if args[0] == "render" and not shutil.which("dot"):
            args = [a.replace(".svg", ".dot") for a in args]
        assert bmtree(args) == 0, capsys.readouterr()
    assert (tmp_path / "grasp_cup.svg").exists() or not shutil.which("dot")
    for line in lines:
        if line.startswith("bmtree run"):
            assert "--module arm.json=arm_standin.yaml grasp_cup.yaml" in line   # the files of the guide
