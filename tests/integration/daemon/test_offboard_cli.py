"""``offboard`` command line: a bad ``--mavlink`` URL is refused at once (exit 2, one line on
stderr, before any Zenoh or MAVLink socket is opened), whatever else is on the line. The
daemon's ``main`` runs in this process (:func:`cli_inproc.run_cli`)."""

from __future__ import annotations

import pytest
from cli_inproc import run_cli
from conftest import CUBE8

pytestmark = pytest.mark.timeout(60)

# a router endpoint nobody listens on: a daemon that got that far would wait forever
NO_ROUTER = "tcp/127.0.0.1:9"


@pytest.mark.parametrize(
    ("url", "why"),
    [
        ("udpin:127.0.0.1:abc", "not a number"),
        ("udpin:127.0.0.1", "HOST:PORT"),
        ("udpin:127.0.0.1:", "not a number"),
        ("udpin:127.0.0.1:65536", "out of range"),
        ("udpin:127.0.0.1:0", "out of range"),
        ("serial:/dev/ttyUSB0:57600x", "unknown scheme"),
        ("127.0.0.1:14540", "unknown scheme"),
        ("udpout::14540", "HOST:PORT"),
    ],
)
def test_bad_mavlink_url_exits_2_with_one_line(url: str, why: str) -> None:
    proc = run_cli("offboard", ["--scenario", CUBE8, "--agent", "1", "--mavlink", url,
                                "--zenoh-connect", NO_ROUTER])
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"offboard: --mavlink {url!r}: ") and why in lines[0]


def test_good_url_forms_pass_the_check() -> None:
    """The check refuses nothing a daemon can open (the unit of the rule above)."""
    from offboard.daemon.mavlink.url import mavlink_url_problem

    for url in ("udpin:127.0.0.1:14540", "udpout:127.0.0.1:14580", "udp:0.0.0.0:1",
                "tcp:127.0.0.1:5760", "tcpin:127.0.0.1:65535"):
        assert mavlink_url_problem(url) is None, url
