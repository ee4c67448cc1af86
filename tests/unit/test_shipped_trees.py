"""The shipped trees against mocked modules (the testing kit, as users would write it)."""
from __future__ import annotations

import os

import pytest

from coordinator.testing import fail, succeed
from tests.conftest import TREES

FIND_APPLE = os.path.join(TREES, "find_apple.yaml")
INVITE = os.path.join(TREES, "invite_to_dining_room.yaml")
GREET = os.path.join(TREES, "greet_guest.yaml")
ROOMS = ["living_room", "kitchen", "dining_room", "bedroom"]


def house(t, apple_room=None, person_room="bedroom"):
    """Script the mocks as a tiny world: vision sees what is in the room navigation last reached."""
    where = {"room": "entrance"}

    def go_to(place):
        where["room"] = place
        return {"success": True, "room": place, "position": {"x": 1.0}}

    t.mocks["navigation.go_to"].respond(go_to)
    t.mocks["vision.find_object"].respond(lambda object: {
        "success": where["room"] == apple_room, "room": where["room"],
        "position": {"x": 8.6, "y": 2.3, "z": 0.9} if where["room"] == apple_room else {}})
    t.mocks["vision.find_person"].respond(lambda name: {
        "success": where["room"] == person_room, "person": "Ana", "position": {"x": 2.3, "y": 6.4}})
    return where


@pytest.mark.parametrize("room", ROOMS)
def test_find_apple_in_each_room(bmtree_tree, room):
    t = bmtree_tree(FIND_APPLE)
    house(t, apple_room=room)
    run = t.run()
    assert run.succeeded, run.reason
    visited = [c.inputs["place"] for c in run.calls("navigation.go_to")]
    assert visited == ROOMS[: ROOMS.index(room) + 1]
    assert run.calls("navigation.approach")[0].inputs["target"] == {"x": 8.6, "y": 2.3, "z": 0.9}
    assert run.said() == ["I am going to look for the apple.", "I found the apple and I am next to it."]
    assert run.blackboard["object_room"] == room


def test_find_apple_when_vision_always_fails(bmtree_tree):
    t = bmtree_tree(FIND_APPLE)
    house(t)
    t.mocks["vision.find_object"].fail("camera unplugged")
    run = t.run()
    assert run.failed
    assert [c.inputs["place"] for c in run.calls("navigation.go_to")] == ROOMS
    assert run.said()[-1] == "I am sorry, I could not find the apple."
    assert run.statuses("say I could not find it") == ["RUNNING", "SUCCESS"]
    assert run.calls("navigation.approach") == []


def test_find_apple_when_navigation_fails_twice_then_succeeds(bmtree_tree):
    t = bmtree_tree(FIND_APPLE)
    where = house(t, apple_room="living_room")
    attempts = []

    def go_to(place):
        attempts.append(place)
        if len(attempts) <= 2:
            return fail("path blocked")
        where["room"] = place
        return {"room": place}

    t.mocks["navigation.go_to"].respond(go_to)
    run = t.run()
    assert run.succeeded, run.reason
    assert [c.status for c in run.calls("navigation.go_to")] == ["failed", "failed", "succeeded"]
    assert [c.error for c in run.calls("navigation.go_to")][:2] == ["path blocked"] * 2
    assert run.statuses("go to the room (retrying)")[-1] == "SUCCESS"


@pytest.mark.parametrize("answer,status,last_said", [
    ("yes, I am coming", "SUCCESS", "Here is the dining room. Enjoy your dinner!"),
    ("YES!", "SUCCESS", "Here is the dining room. Enjoy your dinner!"),       # the switch is on lower(answer)
    ("no, thank you", "SUCCESS", "All right, maybe later."),
    (None, "FAILURE", "I did not hear an answer. I will come back later."),
])
def test_invite_to_dining_room(bmtree_tree, answer, status, last_said):
    t = bmtree_tree(INVITE)
    house(t, person_room="bedroom")
    if answer is None:
        t.mocks["speech.listen"].succeed(success=False, text="")
    else:
        t.mocks["speech.listen"].succeed(text=answer)
    run = t.run()
    assert run.status.value == status, run.reason
    assert run.said()[-1] == last_said
    assert run.calls("navigation.approach")[0].inputs["target"]["x"] == 2.3
    led = [c.inputs["place"] for c in run.calls("navigation.go_to")]
    assert (led[-1] == "dining_room") == (answer is not None and answer.lower().startswith("yes"))


def test_invite_when_listening_hangs(bmtree_tree):
    t = bmtree_tree(INVITE)
    house(t)
    t.mocks["speech.listen"].hang()
    run = t.run()
    assert run.failed and run.calls("speech.listen")[0].status == "timeout"
    assert run.said()[-1] == "I did not hear an answer. I will come back later."


def test_greet_guest_looks_while_nobody_is_seen(bmtree_tree):
    t = bmtree_tree(GREET)
    t.mocks["vision.find_person"].script(succeed(success=False, person=""),
                                         succeed(success=False, person=""),
                                         succeed(success=True, person="Ana"))
    run = t.run()
    assert run.succeeded, run.reason
    assert len(run.calls("vision.find_person")) == 3
    assert run.said() == ["Welcome, Ana! Dinner is served in the dining room."]
    assert run.duration == pytest.approx(1.0, abs=0.05)  # two pauses of 0.5 s on simulated time


def test_greet_guest_gives_up_after_its_maximum(bmtree_tree):
    t = bmtree_tree(GREET, inputs={"looks": 3})
    t.mocks["vision.find_person"].succeed(success=False, person="")
    run = t.run()
    assert run.failed and len(run.calls("vision.find_person")) == 3
    assert "maximum of 3 runs" in run.reason and run.said() == []
