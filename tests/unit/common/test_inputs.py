"""swarm_common.inputs: bounded reads, output-path checks, the shared number and flag types."""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

import pytest

from swarm_common import inputs
from swarm_common.inputs import (
    BoundedReadError,
    finite_float,
    float_in,
    host_problem,
    int_in,
    is_finite_number,
    out_dir_problem,
    out_file_problem,
    read_bounded,
    read_bounded_text,
    zenoh_endpoint_problem,
)

pytestmark = pytest.mark.unit


def _special(tmp_path: Path, kind: str) -> Path:
    """A path of each kind that must never be read: a device streaming zeros, a FIFO with
    no writer (a blocking open would hang), a 1 GiB sparse file, a directory."""
    if kind == "dev_zero":
        return Path("/dev/zero")
    p = tmp_path / kind
    if kind == "fifo":
        os.mkfifo(p)
    elif kind == "sparse":
        with open(p, "wb") as f:
            f.truncate(1 << 30)
    else:
        p.mkdir()
    return p


@pytest.mark.parametrize("kind", ["dev_zero", "fifo", "sparse", "directory"])
def test_read_bounded_refuses_at_once_without_reading(tmp_path, kind):
    p = _special(tmp_path, kind)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.monotonic()
    with pytest.raises(BoundedReadError) as ei:
        read_bounded(p, 1 << 20, "scenario file")
    assert time.monotonic() - t0 < 1.0  # a FIFO open that blocked would never return
    # peak RSS (kB) grows by less than 8 MiB: nothing near the 1 GiB was read
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0 < 8 * 1024
    msg = str(ei.value)
    assert "\n" not in msg and str(p) in msg
    want = "larger than 1048576 bytes" if kind == "sparse" else "not a regular file"
    assert want in msg


def test_read_bounded_cap_is_exact(tmp_path):
    p = tmp_path / "f"
    p.write_bytes(b"x" * 100)
    assert read_bounded(p, 100, "file") == b"x" * 100
    with pytest.raises(BoundedReadError, match="larger than 99 bytes"):
        read_bounded(p, 99, "file")
    with pytest.raises(BoundedReadError, match="No such file"):
        read_bounded(tmp_path / "missing", 10, "file")
    with pytest.raises(BoundedReadError, match="not a valid path"):
        read_bounded("a\0b", 10, "file")


def test_read_bounded_text_names_the_bad_byte(tmp_path):
    p = tmp_path / "f"
    p.write_bytes(b"ok\xff")
    with pytest.raises(BoundedReadError, match=r"not UTF-8 \(byte 2\)"):
        read_bounded_text(p, 10, "file")
    p.write_text("héllo")
    assert read_bounded_text(p, 10, "file") == "héllo"


@pytest.mark.parametrize(
    ("value", "expect"),
    [(1, 1.0), (-2.5, -2.5), ("3e2", 300.0), (10**308, 1e308), (10**400, None),
     (-(10**400), None), (float("nan"), None), (float("inf"), None), ("inf", None),
     ("1e400", None), (True, None), ("x", None), (None, None)],
)
def test_finite_float(value, expect):
    assert finite_float(value) == expect


def test_is_finite_number_refuses_strings_bools_and_huge_ints():
    assert is_finite_number(3) and is_finite_number(2.5)
    assert not is_finite_number("3") and not is_finite_number(False)
    assert not is_finite_number(10**400)  # math.isfinite would raise OverflowError here


def test_int_in_and_float_in_bounds():
    parse = int_in(0, 10)
    assert parse("0") == 0 and parse("10") == 10 and parse(" 7 ") == 7
    for bad in ("-1", "11", "1.5", "1e3", "", "0x10", "9" * 5000):
        with pytest.raises(argparse.ArgumentTypeError, match="0..10"):
            parse(bad)
    f = float_in(0.0, 5.0, lo_open=True, unit="s")
    assert f("5") == 5.0 and f("1e-9") == 1e-9
    for bad in ("0", "5.0001", "nan", "inf", "-inf", "1e400", "abc"):
        with pytest.raises(argparse.ArgumentTypeError, match=r"\(0, 5\] s"):
            f(bad)


def test_seed_and_port_offset_bounds():
    assert inputs.seed("4294967295") == 2**32 - 1
    with pytest.raises(argparse.ArgumentTypeError):
        inputs.seed(str(2**32))
    with pytest.raises(argparse.ArgumentTypeError):
        inputs.seed(str(2**64))
    assert inputs.port_offset(str(inputs.MAX_PORT_OFFSET)) == inputs.MAX_PORT_OFFSET
    for bad in ("-1", str(inputs.MAX_PORT_OFFSET + 1), "99999"):
        with pytest.raises(argparse.ArgumentTypeError):
            inputs.port_offset(bad)


def test_max_port_offset_keeps_every_port_valid():
    """The bound shared by the three commands: at the largest offset, vehicle 255's
    highest port and Zenoh's second port are <= 65535, one more and one is not."""
    from gcs.mission.launch_spec import MAX_PORT_OFFSET
    from swarm_common.ports import vehicle_ports
    from swarm_common.zenoh_session import DEFAULT_ZENOH_PORT

    assert inputs.MAX_PORT_OFFSET == MAX_PORT_OFFSET
    assert inputs.DEFAULT_ZENOH_PORT == DEFAULT_ZENOH_PORT

    def highest(off: int) -> int:
        ps = [vehicle_ports(i, off) for i in range(1, 256)]
        return max(max(p.api_local, p.api_remote, p.gcs_local, p.gcs_remote) for p in ps)

    assert highest(inputs.MAX_PORT_OFFSET) <= 65535
    assert max(highest(inputs.MAX_PORT_OFFSET + 1), DEFAULT_ZENOH_PORT + 1
               + inputs.MAX_PORT_OFFSET + 1) > 65535


@pytest.mark.parametrize("good", ["127.0.0.1", "localhost", "drone-1.lab.example", "a.b."])
def test_host_accepts(good):
    assert host_problem(good) is None


@pytest.mark.parametrize(
    "bad", ["", "999.1.1.1", "1.2.3", "bad!host", "-a.b", "a..b", "x" * 64, "::1", "a b",
            "a" * 254],
)
def test_host_refuses(bad):
    assert host_problem(bad) is not None


@pytest.mark.parametrize(
    "good", ["tcp/127.0.0.1:7447", "udp/localhost:1", "tcp/[::1]:7447", "tls/a.b:65535",
             "tcp/127.0.0.1:7447?iface=lo", "unixsock-stream//tmp/z.sock"],
)
def test_zenoh_endpoint_accepts(good):
    assert zenoh_endpoint_problem(good) is None


@pytest.mark.parametrize(
    ("bad", "why"),
    [("foo", "tcp/127.0.0.1:7447"), ("tcp/127.0.0.1", ":PORT"), ("tcp/1.2.3.4:99999", "port"),
     ("tcp/1.2.3.4:0", "port"), ("http/1.2.3.4:80", "protocol"), ("tcp/bad!:1", "host"),
     ("tcp/[zz]:1", "IPv6"), ("tcp/1.2.3.4:7447 x", "tcp/127"), ("tcp/", "tcp/127")],
)
def test_zenoh_endpoint_refuses(bad, why):
    problem = zenoh_endpoint_problem(bad)
    assert problem is not None and why in problem


def test_listen_endpoint_may_use_port_zero():
    assert zenoh_endpoint_problem("tcp/127.0.0.1:0", allow_zero_port=True) is None


def test_out_dir_problem(tmp_path):
    new = tmp_path / "a" / "b"
    assert out_dir_problem(new) is None
    assert not (tmp_path / "a").exists()  # what the check created is gone again
    new.mkdir(parents=True)
    assert out_dir_problem(new) is None and new.is_dir()  # an existing one stays
    assert list(new.iterdir()) == []  # the probe file is gone
    f = tmp_path / "file"
    f.write_text("x")
    assert "not a directory" in (out_dir_problem(f) or "")
    assert "cannot create" in (out_dir_problem(f / "sub") or "")
    assert "cannot create" in (out_dir_problem("/proc/nope/run") or "")


def test_out_file_problem(tmp_path):
    assert out_file_problem(tmp_path / "stats.json", "--stats-out") is None
    assert not (tmp_path / "stats.json").exists()  # nothing created at the path itself
    assert "does not exist" in (out_file_problem(tmp_path / "no" / "s.json", "--x") or "")
    assert "not a regular file" in (out_file_problem(tmp_path, "--x") or "")
    assert "--x" in (out_file_problem("/proc/nope/x", "--x") or "")


def test_one_line_parser_error(capsys):
    ap = inputs.OneLineParser(prog="demo")
    ap.add_argument("--seed", type=inputs.seed)
    with pytest.raises(SystemExit) as ei:
        ap.parse_args(["--seed", str(2**64)])
    assert ei.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("demo: error: argument --seed")


def test_one_line_parser_refuses_abbreviations_in_subparsers_too(capsys):
    """``--seed`` is not taken for ``--seeds`` (it ran a sweep with one seed), in a
    subcommand as at the top; a caller may still ask for abbreviations."""
    ap = inputs.OneLineParser(prog="demo")
    ap.add_argument("--log-level", default="info")
    sub = ap.add_subparsers(dest="cmd", required=True)
    sweep = sub.add_parser("sweep")
    sweep.add_argument("--seeds", default="0")
    assert ap.parse_args(["--log-level", "debug", "sweep", "--seeds", "1"]).seeds == "1"
    for argv in (["sweep", "--seed", "1"], ["--log-lev", "debug", "sweep"]):
        with pytest.raises(SystemExit) as ei:
            ap.parse_args(argv)
        assert ei.value.code == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and ("unrecognized arguments: --seed 1" in err
                                          or "invalid choice: 'debug'" in err), err
    loose = inputs.OneLineParser(prog="loose", allow_abbrev=True)
    loose.add_argument("--seeds", default="0")
    assert loose.parse_args(["--seed", "3"]).seeds == "3"


def test_one_line_parser_escapes_a_nul_in_its_line(capsys):
    """argparse quotes an unknown flag raw; the error line writes a NUL as ``\\x00``."""
    ap = inputs.OneLineParser(prog="demo")
    with pytest.raises(SystemExit):
        ap.parse_args(["--bo\x00gus"])
    err = capsys.readouterr().err
    assert err == "demo: error: unrecognized arguments: --bo\\x00gus\n", err
