"""Bounded, typed input: the one layer every command reads files and flags through.

**Files** (:func:`read_bounded`): every file the product is given (scenarios,
``--params-file``, signing keys, Zenoh config files, missions, records) is opened with
``O_NONBLOCK`` and checked with ``fstat`` before one byte is read, so a FIFO, a device
(``/dev/zero``), a socket or a directory is refused at once and never blocks; a file larger
than its kind's cap (the ``MAX_*_BYTES`` constants) is refused from its size, and no more
than cap + 1 bytes are ever read (a 1 GB sparse file costs one ``fstat``). Every refusal is
one :class:`BoundedReadError` line naming the path and why. A command's file options use
:func:`bounded_file` as their argparse ``type=``, so the refusal comes as the flags are
parsed, before the command imports numba, Zenoh or pymavlink.

**Output paths** (:func:`out_dir_problem`, :func:`out_file_problem`): checked before a run
starts (creatable and writable, by writing and removing a probe file);
:func:`fallback_dir` is where results go when writing still fails at the end.

**Numbers and flags**, shared by ``gcs``, ``vehicle-sim`` and ``offboard``:
:func:`finite_float` / :func:`is_finite_number` (an integer too large for a float is
refused, never an ``OverflowError``); :func:`int_in` and :func:`float_in` build argparse
``type=`` functions with a range; :func:`port_offset` (0..:data:`MAX_PORT_OFFSET`),
:func:`seed` (0..2³²-1, as the scenario's ``seed``), :func:`agent_id` (1..255),
:func:`host` (an IPv4 address or a host name), :func:`zenoh_endpoint` /
:func:`zenoh_listen_endpoint` (``tcp/HOST:PORT``, ``udp/…``, ``tls/…``, ``quic/…``,
``ws/…``, ``unixsock-stream/PATH``). :class:`OneLineParser` is the commands'
``ArgumentParser``: a bad flag is one stderr line, ``<prog>: error: <message>``, exit 2.
"""

from __future__ import annotations

import argparse
import ipaddress
import math
import os
import re
import stat
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

from swarm_common.ports import GCS_PORT, MAX_ID, vehicle_ports

# Size caps per kind of file (bytes). The shipped files are a few kB each.
MAX_SCENARIO_BYTES = 1 << 20  # 1 MiB: a scenario TOML (250 agents is about 60 kB)
MAX_PARAMS_BYTES = 1 << 20  # 1 MiB: a --params-file (255 vehicles x every parameter)
MAX_ZENOH_CONFIG_BYTES = 256 << 10  # 256 KiB: a Zenoh JSON5 config (credentials + ACL)
MAX_MISSION_BYTES = 1 << 20  # 1 MiB: a mission plan (JSON or TOML)
MAX_KEY_FILE_BYTES = 1024  # a signing key file: 64 hexadecimal digits and a newline
MAX_RECORD_BYTES = 64 << 20  # 64 MiB: a run record read back (metrics.json, stats JSON)


def one_line(text: str) -> str:
    """``text`` with every character that is not printable (a newline, CR, NUL, U+2028 or
    another control or separator) written as its escape (``\\n``): an error that quotes a
    path or a key the user gave stays one line, whatever the path or key holds."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii")
                   for c in text)


def _nul_problem(path: str | os.PathLike[str], flag: str) -> str | None:
    """A path with a NUL byte can be neither created nor opened (``ValueError``)."""
    text = os.fspath(path)
    return f"{flag} {text!r}: not a valid path (a NUL byte)" if "\x00" in text else None


class BoundedReadError(ValueError):
    """A file that cannot be read within its bounds; ``str()`` is one line naming it
    (:func:`one_line`: a newline in the path is written as ``\\n``)."""

    def __init__(self, message: str) -> None:
        super().__init__(one_line(message))


def _open_bounded(p: Path, limit: int, what: str) -> int:
    """An fd of ``p`` opened without blocking, once it is known to be a regular file of at
    most ``limit`` bytes; :class:`BoundedReadError` (one line) if it is not."""
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError as exc:
        raise BoundedReadError(f"{p}: cannot read {what} ({exc.strerror})") from None
    except ValueError:  # an embedded NUL byte
        raise BoundedReadError(f"{p!r}: cannot read {what} (not a valid path)") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = ": a directory" if stat.S_ISDIR(st.st_mode) else ""
            raise BoundedReadError(f"{p}: cannot read {what} (not a regular file{kind})")
        if st.st_size > limit:
            raise BoundedReadError(f"{p}: {what} larger than {limit} bytes")
    except BaseException:
        os.close(fd)
        raise
    return fd


def read_bounded(path: str | os.PathLike[str], limit: int, what: str) -> bytes:
    """The bytes of ``path``: a regular file of at most ``limit`` bytes.

    ``what`` names the kind of file in the error (``"scenario file"``). A FIFO, device,
    socket or directory, a missing or unreadable file, or one larger than ``limit`` raises
    :class:`BoundedReadError` (``"<path>: cannot read <what> (<why>)"``) without blocking
    and without reading more than ``limit + 1`` bytes."""
    p = Path(path)
    fd = _open_bounded(p, limit, what)
    try:
        chunks: list[bytes] = []
        got = 0
        while got <= limit:  # a file growing while read stops at limit + 1 bytes
            chunk = os.read(fd, limit + 1 - got)
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
    except OSError as exc:
        raise BoundedReadError(f"{p}: cannot read {what} ({exc.strerror})") from None
    finally:
        os.close(fd)
    if got > limit:
        raise BoundedReadError(f"{p}: {what} larger than {limit} bytes")
    return b"".join(chunks)


def bounded_file(limit: int, what: str, missing_ok: bool = False) -> Callable[[str], str]:
    """argparse ``type=`` of a file option: the path, once :func:`read_bounded` would take
    it (a regular file of at most ``limit`` bytes; with ``missing_ok`` also a path where
    nothing is yet). Refused at parse time, one line and exit 2, before the command loads
    anything heavy: a process given ``/dev/zero`` or a FIFO ends at once and small. The
    command reads the file later with :func:`read_bounded`, which checks again."""

    def check(text: str) -> str:
        p = Path(text)
        if missing_ok and not os.path.lexists(p):
            return text
        try:
            os.close(_open_bounded(p, limit, what))
        except BoundedReadError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text

    check.__name__ = what.replace(" ", "_")  # argparse names the type in some errors
    return check


def read_bounded_text(path: str | os.PathLike[str], limit: int, what: str) -> str:
    """:func:`read_bounded` decoded as UTF-8 (one :class:`BoundedReadError` line if not)."""
    data = read_bounded(path, limit, what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BoundedReadError(f"{Path(path)}: {what} not UTF-8 (byte {exc.start})") from None


EXIT_USAGE = 2
SEED_MAX = 2**32 - 1  # as the scenario's [scenario] seed
MAX_PORT = 65535
# swarm_common.zenoh_session.DEFAULT_ZENOH_PORT (a unit test keeps them equal): not imported,
# since zenoh_session reads its config files through this module
DEFAULT_ZENOH_PORT = 7447


def _max_port_offset() -> int:
    """The largest offset that keeps every port of the scheme (vehicles 1..255, the GCS
    port, Zenoh 7447 and 7448) at most 65535."""
    vp = [vehicle_ports(i, 0) for i in range(1, MAX_ID + 1)]
    highest = max(max(p.api_local, p.api_remote, p.gcs_local, p.gcs_remote) for p in vp)
    return MAX_PORT - max(highest, DEFAULT_ZENOH_PORT + 1, GCS_PORT)


MAX_PORT_OFFSET = _max_port_offset()


class OneLineParser(argparse.ArgumentParser):
    """``ArgumentParser`` whose errors are one stderr line (``prog: error: msg``), exit 2.

    Abbreviated flags are refused (``allow_abbrev=False`` unless the caller says otherwise):
    with them ``gcs mission sweep S --seed 1`` ran as ``--seeds 1``, and a flag added later
    could change what an old command line means. Subparsers are built with this class
    (``add_subparsers`` passes ``type(self)``), so they refuse abbreviations too."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        line = one_line(" ".join(message.split()))  # never more than one line, no raw NUL
        sys.stderr.write(f"{self.prog}: error: {line}\n")
        raise SystemExit(EXIT_USAGE)


def finite_float(value: object) -> float | None:
    """``value`` (an int, float or numeric string) as a finite float, or None: NaN, ±inf,
    booleans, non-numbers and integers too large for a float (|x| > 1.8e308) are None."""
    if isinstance(value, bool):
        return None
    try:
        x = float(value) if isinstance(value, int | float) else float(str(value).strip())
    except (ValueError, OverflowError):
        return None
    return x if math.isfinite(x) else None


def is_finite_number(value: object) -> bool:
    """True for an ``int`` or ``float`` (not ``bool``) that is finite as a float: the
    check of every number read from a file (scenario values), without OverflowError."""
    return isinstance(value, int | float) and not isinstance(value, bool) and (
        finite_float(value) is not None
    )


def parse_int(text: str) -> int | None:
    """``text`` as a plain decimal integer (optional sign, at most 20 digits), or None."""
    t = text.strip()
    if not re.fullmatch(r"[+-]?[0-9]{1,20}", t):
        return None
    return int(t)


def int_in(lo: int, hi: int, what: str = "an integer") -> Callable[[str], int]:
    """argparse ``type=``: a decimal integer in ``lo..hi``."""

    def parse(text: str) -> int:
        v = parse_int(text)
        if v is None or not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"{text!r}: must be {what} in {lo}..{hi}")
        return v

    parse.__name__ = "integer"
    return parse


def float_in(lo: float, hi: float, lo_open: bool = False, hi_open: bool = False,
             unit: str = "") -> Callable[[str], float]:
    """argparse ``type=``: a finite number in the interval (``lo_open``/``hi_open``: the
    bound itself excluded); ``unit`` is named in the error (``"s"``)."""
    left, right = "(" if lo_open else "[", ")" if hi_open else "]"
    where = f"{left}{lo:g}, {hi:g}{right}" + (f" {unit}" if unit else "")

    def parse(text: str) -> float:
        v = finite_float(text)
        ok = v is not None and (v > lo if lo_open else v >= lo) and (v < hi if hi_open
                                                                       else v <= hi)
        if v is None or not ok:
            raise argparse.ArgumentTypeError(f"{text!r}: must be a finite number in {where}")
        return v

    parse.__name__ = "number"
    return parse


port_offset = int_in(0, MAX_PORT_OFFSET, "a port offset")
seed = int_in(0, SEED_MAX, "a seed")
agent_id = int_in(1, MAX_ID, "an agent id")

_LABEL = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")


def host_problem(text: str) -> str | None:
    """None if ``text`` is an IPv4 address or a host name (RFC 1123 labels, at most 253
    characters, not all-numeric), else what it must be."""
    want = "must be an IPv4 address or a host name"
    if not text or len(text) > 253:
        return want
    try:
        ipaddress.IPv4Address(text)
        return None
    except ValueError:
        pass
    labels = text[:-1].split(".") if text.endswith(".") else text.split(".")
    if not all(_LABEL.fullmatch(lb) for lb in labels) or labels[-1].isdigit():
        return want  # 999.1.1.1 is no address and cannot be a name either
    return None


def host(text: str) -> str:
    """argparse ``type=``: :func:`host_problem`."""
    if (why := host_problem(text)) is not None:
        raise argparse.ArgumentTypeError(f"{text!r}: {why}")
    return text


_IP_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")
_PATH_PROTOCOLS = ("unixsock-stream",)


def _port_problem(port: str, allow_zero: bool) -> str | None:
    v = parse_int(port) if port.isdigit() else None
    lo = 0 if allow_zero else 1
    if v is None or not lo <= v <= MAX_PORT:
        return f"port {port!r} must be in {lo}..{MAX_PORT}"
    return None


def zenoh_endpoint_problem(text: str, allow_zero_port: bool = False) -> str | None:
    """None if ``text`` is a Zenoh locator this project accepts, else what is wrong:
    ``PROTO/HOST:PORT`` (PROTO one of tcp, udp, tls, quic, ws; HOST an IPv4 address, a
    host name or ``[IPv6]``; PORT 1..65535, 0 too when listening) or
    ``unixsock-stream/PATH``, optionally followed by ``?metadata`` or ``#config``."""
    if not text or any(c.isspace() or ord(c) < 32 for c in text):
        return "must look like tcp/127.0.0.1:7447"
    proto, sep, rest = text.partition("/")
    addr = re.split(r"[?#]", rest, maxsplit=1)[0]
    if not sep or not addr:
        return "must look like tcp/127.0.0.1:7447"
    if proto in _PATH_PROTOCOLS:
        return None
    if proto not in _IP_PROTOCOLS:
        return f"protocol {proto!r} must be one of {', '.join((*_IP_PROTOCOLS, *_PATH_PROTOCOLS))}"
    if addr.startswith("["):
        h, close, tail = addr[1:].partition("]")
        try:
            ipaddress.IPv6Address(h)
        except ValueError:
            return f"[{h}] is not an IPv6 address"
        if not close or not tail.startswith(":"):
            return "must end in :PORT"
        return _port_problem(tail[1:], allow_zero_port)
    h, colon, port = addr.rpartition(":")
    if not colon:
        return "must end in :PORT"
    if host_problem(h) is not None:
        return f"host {h!r} is not an IPv4 address or a host name"
    return _port_problem(port, allow_zero_port)


def zenoh_endpoint(text: str) -> str:
    """argparse ``type=`` for an endpoint to connect to (:func:`zenoh_endpoint_problem`)."""
    if (why := zenoh_endpoint_problem(text)) is not None:
        raise argparse.ArgumentTypeError(f"zenoh endpoint {text!r}: {why}")
    return text


def zenoh_listen_endpoint(text: str) -> str:
    """argparse ``type=`` for an endpoint to listen on (port 0: any free port)."""
    if (why := zenoh_endpoint_problem(text, allow_zero_port=True)) is not None:
        raise argparse.ArgumentTypeError(f"zenoh endpoint {text!r}: {why}")
    return text


# --------------------------------------------------------------------------------------
# Output paths: checked before a run starts; a fallback folder when writing fails at the end
# --------------------------------------------------------------------------------------
def _probe_dir(d: Path) -> str | None:
    """None if a file can be created (and removed) in the existing directory ``d``."""
    try:
        fd, name = tempfile.mkstemp(prefix=".write-probe-", dir=d)
    except OSError as exc:
        return f"cannot write in {d} ({exc.strerror})"
    os.close(fd)
    try:
        os.unlink(name)
    except OSError:
        pass
    return None


def out_dir_problem(out: str | os.PathLike[str], flag: str = "--out") -> str | None:
    """Why ``out`` cannot be an output directory, or None. The directory (and its parents)
    is created if missing and a probe file written and removed in it, so a path that a run
    could not write (``/proc/nope/run``, a read-only mount, a file in the way) is refused
    before anything starts; what the check created is removed again (a refused run
    leaves nothing behind). The reason is one line (:func:`one_line`)."""
    if (why := _nul_problem(out, flag)) is not None:
        return why
    p = Path(out)
    if p.exists() and not p.is_dir():
        return one_line(f"{flag} {p}: exists and is not a directory")
    made = [q for q in (p, *p.parents) if not q.exists()]  # created here: removed again
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return one_line(f"{flag} {p}: cannot create the directory ({exc.strerror})")
    why = _probe_dir(p)
    for q in made:  # deepest first; a check writes nothing (the run creates them)
        try:
            q.rmdir()
        except OSError:
            break
    return None if why is None else one_line(f"{flag} {p}: {why}")


def out_file_problem(out: str | os.PathLike[str], flag: str) -> str | None:
    """Why ``out`` cannot be written as a file at the end of a run, or None: its folder must
    exist and be writable, and ``out`` must not be a directory or other non-regular file.
    Nothing is created at ``out`` itself. The reason is one line (:func:`one_line`)."""
    if (why := _nul_problem(out, flag)) is not None:
        return why
    p = Path(out)
    if not str(out) or p.name in ("", ".", ".."):
        return f"{flag} {out!r}: not a file name"
    if p.exists() and not p.is_file():
        return one_line(f"{flag} {p}: exists and is not a regular file")
    parent = p.parent
    if not parent.is_dir():
        return one_line(f"{flag} {p}: its folder {parent} does not exist")
    if (why := _probe_dir(parent)) is not None:
        return one_line(f"{flag} {p}: {why}")
    return None


def fallback_dir(prefix: str) -> Path:
    """A fresh private folder (mode 0700) in the temporary directory, for results that
    could not be written where asked; the caller logs its path."""
    return Path(tempfile.mkdtemp(prefix=prefix))


def out_dir_arg(text: str) -> str:
    """argparse ``type=`` for an output folder (``--out``, ``--log-dir``):
    :func:`out_dir_problem` at parse time, before anything starts."""
    if (why := out_dir_problem(text, "")) is not None:
        raise argparse.ArgumentTypeError(why.strip())
    return text
