"""The bad input campaign (docs/security.md, "Bad input"): every kept bad scenario file and
every bad flag line of ``vehicle-sim``, ``offboard`` and ``gcs`` gets exit status 2 and one
stderr line naming what is wrong, never a traceback.

The corpus is data, kept in the repository so it cannot shrink or drift unseen:

* ``tests/reference/bad_scenarios/<kind>-<what>.toml``: shipped scenarios with one thing
  wrong, written by ``tests/reference/make_bad_scenarios.py``; each file's second line is
  ``# expect: TEXT``, a text its error line must hold. Each file goes through
  ``gcs mission run FILE --inproc``, ``vehicle-sim --scenario FILE --no-zenoh`` and
  ``offboard --scenario FILE --agent 1``.
* ``tests/reference/bad_flags.py``: ``(prog, argv, expect)`` lines by kind.

Every call runs the command's ``main`` in this process (:func:`cli_inproc.run_cli`): these
are refusals that end before anything starts. A regression that accepts a case would start
the command here; the vehicle-sim calls carry ``--duration`` so that a simulator started by
mistake ends, and the module's timeout bounds the rest. One test per kind runs all of that
kind's cases and names every one that fails. FIFOs and ``/dev/zero`` are
``test_bad_input_files.py``'s (they need a process that can be killed).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import pytest
from cli_inproc import CliResult, run_cli
from conftest import ROOT
from reference import make_bad_scenarios
from reference.bad_flags import BAD_FLAGS, BY_KIND

pytestmark = pytest.mark.timeout(120)

BAD_DIR = ROOT / "tests" / "reference" / "bad_scenarios"
MIN_FILES = 90  # the campaign's size (86 files): the corpus may grow, never shrink below
MIN_FLAGS = 150  # ... (143 flag lines)
MIN_PER_KIND = 2  # several cases of each kind
MAX_LINE = 2000  # characters: an error quoting a 20 000-character value cuts it
# the kinds of bad file the campaign covers (make_bad_scenarios.cases)
FILE_KINDS = frozenset({
    "syntax", "type", "nonfinite", "nonpositive", "range", "veclen", "missing", "unknown",
    "agents", "empty", "graph", "name", "mission", "obstacle", "geofence", "encoding",
    "nesting", "huge", "unsafe",
})
# a simulator started by a regression stops after this much simulated time (s)
SIM_BOUND = ["--duration", "0.05"]


def _command_lines(path: Path) -> list[tuple[str, list[str]]]:
    """The three command lines that load the scenario ``path``."""
    p = str(path)
    return [
        ("gcs", ["mission", "run", p, "--inproc", "--duration", "0.1"]),
        ("vehicle-sim", ["--scenario", p, "--no-zenoh", *SIM_BOUND]),
        ("offboard", ["--scenario", p, "--agent", "1"]),
    ]


def _expect_of(path: Path) -> str:
    """The ``# expect:`` text of a bad file (its second line, ASCII)."""
    lines = path.read_bytes().split(b"\n", 2)
    assert len(lines) == 3 and lines[0].startswith(b"# BAD "), path.name
    head = lines[1].decode("ascii")
    assert head.startswith(make_bad_scenarios.EXPECT_PREFIX), path.name
    return head[len(make_bad_scenarios.EXPECT_PREFIX):]


def _files_by_kind() -> dict[str, list[Path]]:
    by_kind: dict[str, list[Path]] = defaultdict(list)
    for path in sorted(BAD_DIR.glob("*.toml")):
        by_kind[path.name.split("-", 1)[0]].append(path)
    return dict(by_kind)


FILES = _files_by_kind()


def _refusal_problem(r: CliResult, expect: str) -> str | None:
    """What is wrong with ``r`` as a refusal, or None: exit 2, no traceback, one non-empty
    stderr line (argparse's usage line may come first) holding ``expect``, at most
    :data:`MAX_LINE` characters, all printable (a NUL of a path escaped). The rule of
    ``test_cli_errors._one_line_exit_2``, as a value, so that one test reports every
    failing case of its kind."""
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    if r.returncode != 2:
        return f"exit {r.returncode}, stderr {r.stderr[-300:]!r}"
    if "Traceback" in r.stderr:
        return f"a traceback: {r.stderr[-300:]!r}"
    if not lines:
        return "nothing on stderr"
    if not lines[0].startswith("usage:") and len(lines) != 1:
        return f"{len(lines)} lines: {r.stderr[-300:]!r}"
    if expect not in lines[-1]:
        return f"{expect!r} not in {lines[-1][:300]!r}"
    if len(lines[-1]) > MAX_LINE:
        return f"a line of {len(lines[-1])} characters"
    if not lines[-1].isprintable():  # a raw NUL or control character of a path
        return f"an unprintable character in {lines[-1][:300]!r}"
    return None


def _failures(calls: list[tuple[str, str, list[str], str]]) -> list[str]:
    """Each ``(name, prog, argv, expect)`` run; one entry per call that is not a refusal."""
    out = []
    for name, prog, argv, expect in calls:
        why = _refusal_problem(run_cli(prog, argv), expect)
        if why is not None:
            out.append(f"{name}: {prog} {argv!r}: {why}")
    return out


def test_corpus_sizes_and_kinds():
    """At least the campaign's size, every kind there with several cases, and every file
    with its header: a case cannot be lost unseen."""
    n_files = sum(len(v) for v in FILES.values())
    assert n_files >= MIN_FILES, n_files
    assert len(BAD_FLAGS) >= MIN_FLAGS, len(BAD_FLAGS)
    assert set(FILES) == FILE_KINDS, sorted(set(FILES) ^ FILE_KINDS)
    thin = {k: len(v) for k, v in {**FILES, **BY_KIND}.items() if len(v) < MIN_PER_KIND}
    assert not thin, thin
    for paths in FILES.values():
        for path in paths:
            assert _expect_of(path), path.name
    progs = {prog for prog, _, _ in BAD_FLAGS}
    assert progs == {"gcs", "offboard", "vehicle-sim"}, progs
    gcs_commands = {tuple(argv[:2]) for prog, argv, _ in BAD_FLAGS if prog == "gcs"}
    for command in [("mission", "run"), ("mission", "compare"), ("mission", "sweep"),
                    ("router",), ("dashboard",), ("keys", "generate"), ("scenario", "grid"),
                    ("log", "export")]:
        assert any(c[:len(command)] == command for c in gcs_commands), command


def test_corpus_is_what_the_script_writes():
    """The kept files are ``make_bad_scenarios.py``'s output, byte for byte: a change of a
    shipped scenario or of a case shows here until the script is rerun (and a case whose
    edit no longer applies fails in the script)."""
    cases = make_bad_scenarios.cases()
    names = [f"{c.kind}-{c.slug}.toml" for c in cases]
    assert sorted(names) == sorted(p.name for p in BAD_DIR.glob("*.toml"))
    stale = [name for case, name in zip(cases, names, strict=True)
             if (BAD_DIR / name).read_bytes() != make_bad_scenarios.body(case)]
    assert not stale, f"rerun tests/reference/make_bad_scenarios.py: {stale}"


@pytest.mark.parametrize("kind", sorted(FILE_KINDS))
def test_bad_scenario_files_exit_2_with_one_line(kind):
    """Every bad file of ``kind`` through the three command lines."""
    calls = [(path.name, prog, argv, _expect_of(path))
             for path in FILES.get(kind, []) for prog, argv in _command_lines(path)]
    assert calls, kind
    failed = _failures(calls)
    assert not failed, "\n".join(failed)


@pytest.mark.parametrize("kind", sorted(BY_KIND))
def test_bad_flags_exit_2_with_one_line(kind):
    """Every bad flag line of ``kind``; a vehicle-sim line carries :data:`SIM_BOUND`."""
    calls = []
    for k, (prog, argv, expect) in enumerate(BY_KIND[kind]):
        if prog == "vehicle-sim" and "--duration" not in argv:
            argv = [*argv, *SIM_BOUND]
        calls.append((f"{kind}[{k}]", prog, argv, expect))
    failed = _failures(calls)
    assert not failed, "\n".join(failed)
