"""The control lease as a secret: laws of ``Authority`` on a fake clock (no server)."""

from __future__ import annotations

import dataclasses

import pytest

from app.control.authority import Authority, LeaseHeld, LeaseRequired, is_loopback


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock() -> Clock:
    return Clock()


@pytest.fixture
def authority(clock: Clock) -> Authority:
    return Authority("a-long-token", timeout_s=30.0, clock=clock)


def test_nobody_holds_control_by_default(authority):
    assert not authority.view().held
    for lease_id in (None, "", "anonymous", "tests"):
        with pytest.raises(LeaseRequired, match="POST /api/lease"):
            authority.check(lease_id)


def test_only_the_lease_id_gives_control_never_the_name(authority):
    lease_id = authority.take("alice")
    assert authority.check(lease_id) == "alice"
    view = authority.view()
    assert view.held and view.holder == "alice"
    assert lease_id not in repr(dataclasses.asdict(view))  # the public view never has it
    for guess in ("alice", "anonymous", lease_id[:-1], lease_id + "x", None):
        with pytest.raises(LeaseHeld, match="alice"):
            authority.check(guess)


def test_taking_a_held_lease_needs_take_over_and_ends_the_old_one(authority):
    alice = authority.take("alice")
    with pytest.raises(LeaseHeld):
        authority.take("bob")
    with pytest.raises(LeaseHeld):
        authority.take("alice")  # the same name is no key either
    bob = authority.take("bob", take_over=True)
    assert bob != alice
    authority.check(bob)
    with pytest.raises(LeaseHeld, match="bob"):
        authority.check(alice)


def test_a_lapsed_lease_is_free_to_take_but_its_holder_keeps_it_until_then(authority, clock):
    alice = authority.take("alice")
    clock.now += 31.0
    assert not authority.view().held
    assert authority.check(alice) == "alice"  # renews it
    assert authority.view().held
    clock.now += 31.0
    bob = authority.take("bob")  # no take_over needed: alice's lease had lapsed
    authority.check(bob)
    with pytest.raises(LeaseHeld):
        authority.check(alice)


def test_commands_renew_the_lease(authority, clock):
    alice = authority.take("alice")
    for _ in range(5):
        clock.now += 20.0
        authority.check(alice)
    with pytest.raises(LeaseHeld):
        authority.take("bob")


def test_release_gives_control_back_only_to_its_holder(authority):
    alice = authority.take("alice")
    assert not authority.release("alice")
    assert authority.view().held
    assert authority.release(alice)
    assert not authority.view().held
    with pytest.raises(LeaseRequired):
        authority.check(alice)


def test_the_token_is_checked_exactly(authority):
    assert authority.token_ok("a-long-token")
    for wrong in (None, "", "a-long-toke", "a-long-token ", "A-LONG-TOKEN"):
        assert not authority.token_ok(wrong)
    assert Authority(None, 30.0).token_ok(None)


@pytest.mark.parametrize(
    ("host", "loopback"),
    [
        ("127.0.0.1", True),
        ("127.3.2.1", True),
        ("::1", True),
        ("localhost", True),
        ("0.0.0.0", False),
        ("::", False),
        ("192.168.1.5", False),
        ("robot.local", False),
    ],
)
def test_loopback_hosts(host, loopback):
    assert is_loopback(host) is loopback


def test_taking_control_says_whom_it_was_taken_from(authority, clock):
    _, previous = authority.take_from("alice")
    assert not previous.held  # control was free
    clock.now += 5.0
    bob, previous = authority.take_from("bob", take_over=True)
    assert (previous.held, previous.holder, previous.idle_s) == (True, "alice", 5.0)
    clock.now += 31.0  # bob's lease lapses: taking it then took it from nobody
    _, previous = authority.take_from("carol")
    assert not previous.held and authority.view().holder == "carol"
