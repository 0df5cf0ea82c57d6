"""The protocol's [groups]: checked in one line, stored with the protocol, simulated participants placed in turn."""

from __future__ import annotations

from pathlib import Path

import pytest

from protocol.study.config import ProtocolError, default_protocol, load_protocol, protocol_from_dict
from protocol.study.covariates import simulated_values
from protocol.study.groups import simulated_covariates, simulated_level, simulated_profile

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "surgeons.toml"


def _with(groups: dict, covariates: list | None = None) -> dict:
    d = default_protocol().to_dict()
    d["covariates"] = covariates if covariates is not None else [
        {"name": "group", "kind": "category", "levels": ["novice", "resident", "surgeon"]},
        {"name": "years", "kind": "integer", "min": 0, "max": 50}]
    d["groups"] = groups
    return d


def test_the_example_declares_its_groups() -> None:
    p = load_protocol(EXAMPLE)
    assert p.groups is not None
    assert (p.groups.by, p.groups.levels) == ("group", ("novice", "resident", "surgeon"))
    assert p.groups.simulated == ("novice", "surgeon") and p.groups.experienced == ("surgeon",)
    again = protocol_from_dict(p.to_dict())  # stored with each session and read back as it was
    assert again.groups == p.groups
    assert default_protocol().groups is None and "groups" not in default_protocol().to_dict()


@pytest.mark.parametrize(("groups", "line"), [
    ({"by": "hand"}, "groups.by = 'hand': must name a category covariate the protocol declares (declared "
                     "categories: group)"),
    ({"by": "years"}, "groups.by = 'years': is an integer covariate: groups need a category (declared categories: "
                      "group)"),
    ({}, "every"),
    ({"by": "group", "simulated": ["novice", "expert"]}, "groups.simulated[1] = 'expert': must be a level of "
                                                         "group: novice, resident, surgeon"),
    ({"by": "group", "simulated": ["novice"]}, "groups.simulated = ['novice']: must be a list of 2 to 3 distinct"),
    ({"by": "group", "simulated": ["novice", "novice"]}, "groups.simulated = ['novice', 'novice']: each level once"),
    ({"by": "group", "experienced": "surgeon"}, "groups.experienced = 'surgeon': must be a list of 1 to 3"),
    ({"by": "group", "compare": ["a"]}, "groups.compare"),
])
def test_bad_groups_are_refused_in_one_line(groups: dict, line: str) -> None:
    with pytest.raises(ProtocolError) as err:
        protocol_from_dict(_with(groups), "p.toml")
    text = str(err.value)
    assert "\n" not in text and text.startswith("p.toml: groups")
    if line != "every":
        assert line in text
    else:
        assert "groups.by" in text


def test_groups_without_covariates_refused() -> None:
    with pytest.raises(ProtocolError, match=r"groups.by = 'group': .*\(declared categories: none\)"):
        protocol_from_dict(_with({"by": "group"}, covariates=[]), "p.toml")


def test_simulated_participants_are_placed_in_turn() -> None:
    p = load_protocol(EXAMPLE)
    assert p.groups is not None
    for seed in (0, 1, 7):
        levels = [simulated_level(p.groups, seed, n) for n in range(1, 41)]
        for k in range(1, 21):  # any first 2k participants: k of each kind
            first = levels[: 2 * k]
            assert first.count("novice") == first.count("surgeon") == k
    a = [simulated_level(p.groups, 0, n) for n in range(1, 21)]
    assert a == [simulated_level(p.groups, 0, n) for n in range(1, 21)]  # seeded
    assert a != [simulated_level(p.groups, 1, n) for n in range(1, 21)]  # (the order is drawn)
    three = protocol_from_dict(_with({"by": "group"})).groups
    assert three is not None and three.simulated == ("novice", "resident", "surgeon")
    assert sorted(simulated_level(three, 3, n) for n in range(1, 4)) == ["novice", "resident", "surgeon"]


def test_simulated_covariates_and_profile() -> None:
    p = load_protocol(EXAMPLE)
    drawn = simulated_values(p.covariates, 0, 5)
    placed = simulated_covariates(p.covariates, p.groups, 0, 5)
    assert {k: v for k, v in placed.items() if k != "group"} == {k: v for k, v in drawn.items() if k != "group"}
    assert placed["group"] == simulated_level(p.groups, 0, 5)
    assert simulated_covariates(p.covariates, None, 0, 5) == drawn  # no [groups]: as drawn before
    assert simulated_profile(p.groups, {"group": "surgeon"}) == "experienced"
    assert simulated_profile(p.groups, {"group": "resident"}) == "novice"
    assert simulated_profile(p.groups, {}) == "novice" and simulated_profile(None, {"group": "surgeon"}) == "novice"
