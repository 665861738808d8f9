"""offboard.daemon.start_gate's value parsing (unit test of one module; the slots themselves are
tested with real processes in tests/integration/daemon/test_start_gate_processes.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from offboard.daemon import start_gate


def test_a_value_names_its_slots_and_directory(tmp_path: Path) -> None:
    value = start_gate.gate_value(3, tmp_path)
    assert start_gate.parse_gate(value) == (3, tmp_path)


@pytest.mark.parametrize("value", ["", "3", "x:{d}", "0:{d}", "-1:{d}", "1025:{d}",
                                   "2:{d}/missing", "２:{d}"])
def test_a_malformed_value_is_one_line_error(tmp_path: Path, value: str) -> None:
    with pytest.raises(ValueError) as err:
        start_gate.parse_gate(value.format(d=tmp_path))
    assert "\n" not in str(err.value)


def test_no_variable_no_gate() -> None:
    assert start_gate.acquire(None) is None and start_gate.acquire("") is None
    assert not start_gate.holding()


def test_acquire_then_release_frees_the_slot(tmp_path: Path) -> None:
    value = start_gate.gate_value(1, tmp_path)
    assert start_gate.acquire(value) is not None and start_gate.holding()
    start_gate.release()
    start_gate.release()  # idempotent
    assert not start_gate.holding()
    assert start_gate.acquire(value, max_wait_s=0.0) is not None and start_gate.holding()
    start_gate.release()


def test_a_run_gates_at_least_eight_daemons_at_once() -> None:
    """A cube8 run starts its 8 daemons together (fewer slots cost real-time runs their
    start on a busy machine: docs/performance.md, twentieth round)."""
    from gcs.mission.procs import MIN_START_SLOTS, start_slots

    assert MIN_START_SLOTS == 8 and start_slots() >= MIN_START_SLOTS
