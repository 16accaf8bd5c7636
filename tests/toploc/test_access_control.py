"""A site router's access control, one user per robot (toploc.bus.access_control): the rules as
data. What they let through a real router: tests/faults/test_faults_site_security.py."""

from __future__ import annotations

import pytest

from toploc.bus.access_control import SiteUsers, parse_credentials, site_access_control


def rules_of(access_control: dict, subject: str) -> list[dict]:
    """The rules of the policies naming ``subject``."""
    names = {
        rule
        for policy in access_control["policies"]
        if subject in policy["subjects"]
        for rule in policy["rules"]
    }
    return [rule for rule in access_control["rules"] if rule["id"] in names]


def test_a_robot_may_serve_its_own_keys_only() -> None:
    access_control = site_access_control(["site-1"], SiteUsers(("r1", "r2")))
    served = {
        key
        for rule in rules_of(access_control, "robot r1")
        if "declare_queryable" in rule["messages"]
        for key in rule["key_exprs"]
    }
    assert served == {"toploc/r1/**"}


def test_a_viewer_serves_nothing() -> None:
    access_control = site_access_control(["site-1"], SiteUsers(("r1",), viewers=("watcher",)))
    for rule in rules_of(access_control, "viewers"):
        assert not {"declare_queryable", "reply", "put", "liveliness_token"} & set(rule["messages"])


def test_everyone_else_is_denied_by_default() -> None:
    assert site_access_control(["site-1"], SiteUsers(("r1",)))["default_permission"] == "deny"


def test_one_user_with_two_roles_is_refused() -> None:
    with pytest.raises(ValueError, match="r1 has more"):
        SiteUsers(("r1",), operators=("r1",))


def test_the_site_maps_root_is_not_a_robot() -> None:
    with pytest.raises(ValueError, match="robot id 'map' is taken"):
        SiteUsers(("map",))


def test_a_site_needs_a_map_id() -> None:
    with pytest.raises(ValueError, match="at least one map id"):
        site_access_control([], SiteUsers(("r1",)))


def test_credentials_read_back_as_written() -> None:
    assert parse_credentials("map-node:a-b\n\nr1:c_d\n", "creds") == {
        "map-node": "a-b",
        "r1": "c_d",
    }
