"""``{key}`` or ``$key`` inside a quoted text of an expression is that text, not the key's value: ``bmtree check``
warns at its column, with the fix (a ``where:`` skipped every event, a ``check`` always failed)."""
from __future__ import annotations

import pytest

from coordinator.language import load_tree
from modules.definition import load_definitions
from modules.sim import SIM_DIR

DEFS = load_definitions([SIM_DIR])
HEAD = "format: 1\nname: t\ninputs:\n  guest: {default: Ana}\n  g: {default: Bob}\nroot:\n"


def _warnings(tmp_path, root: str):
    path = tmp_path / "t.yaml"
    path.write_text(HEAD + root)
    return [str(w).replace(str(path), "t.yaml") for w in load_tree(str(path), DEFS).warnings]


@pytest.mark.parametrize("written, col", [('{guest}', 22), ('$guest', 22), ('{ guest }', 22)])
def test_a_key_quoted_in_a_where_says_to_name_it(tmp_path, written, col):
    said = _warnings(tmp_path, "  wait_event: vision.personSeen\n  where: 'person == \"%s\"'\n  timeout: 10\n" % written)
    assert said == ["t.yaml:8:%d: warning: %s inside a quoted text is that text, not the value of guest: an "
                    "expression reads a key by its name, unquoted (guest)" % (col, written)], said


def test_a_key_quoted_in_a_check_or_an_until_says_to_name_it(tmp_path):
    said = _warnings(tmp_path, "  sequence:\n    - check: 'g == \"{guest}\"'\n    - repeat: 3\n"
                               "      until: 'g == \"x$guest\"'\n      child: {wait: 1}\n")
    assert said == [
        "t.yaml:8:21: warning: {guest} inside a quoted text is that text, not the value of guest: an expression "
        "reads a key by its name, unquoted (guest)",
        "t.yaml:10:22: warning: $guest inside a quoted text is that text, not the value of guest: an expression "
        "reads a key by its name, unquoted (guest)"], said


def test_text_that_names_no_key_is_left_alone(tmp_path):
    assert _warnings(tmp_path, "  check: 'g == \"{price} costs $5 {nokey}\" or g == guest'\n") == []
