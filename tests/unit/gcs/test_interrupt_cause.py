"""gcs.cli.interrupt_cause: a signal handler's exception that compiled code wrapped in a
SystemError (numba boxing a kernel's result when SIGTERM or Ctrl-C arrived) is found, so
``gcs mission`` still exits 143 / 130 without a traceback; other errors are not touched."""

from __future__ import annotations

import pytest

from gcs.cli import interrupt_cause


def _wrapped(inner: BaseException) -> SystemError:
    try:
        try:
            raise inner
        except BaseException as exc:  # noqa: BLE001 - the chain numba builds
            raise SystemError("<function _numba_unpickle> returned a result with an "
                              "exception set") from exc
    except SystemError as mid:
        try:
            raise SystemError("CPUDispatcher(step_kernel) returned a result with an "
                              "exception set") from mid
        except SystemError as outer:
            return outer


@pytest.mark.parametrize("inner", [SystemExit(143), KeyboardInterrupt()])
def test_the_signal_exception_is_found_two_levels_down(inner: BaseException) -> None:
    assert interrupt_cause(_wrapped(inner)) is inner


def test_a_plain_system_error_has_no_interrupt() -> None:
    assert interrupt_cause(_wrapped(ValueError("bad"))) is None
    assert interrupt_cause(SystemError("alone")) is None
