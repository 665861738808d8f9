"""The kernel cache folder's fingerprint (swarm_common.jit): it changes with any module that
defines a kernel, so a kernel calling another file's kernel never runs stale cached code,
and it ignores modules without kernels."""

from __future__ import annotations

from pathlib import Path

from swarm_common.jit import kernel_sources_fingerprint


def _tree(root: Path) -> None:
    for pkg in ("swarm_common", "offboard"):
        (root / pkg).mkdir(parents=True)
    (root / "swarm_common" / "frames_kernel.py").write_text("@kernel\ndef f(x):\n    return x\n")
    (root / "offboard" / "attitude_kernel.py").write_text("@kernel\ndef g(x):\n    return x\n")
    (root / "offboard" / "daemon.py").write_text("x = 1\n")


def test_fingerprint_follows_kernel_modules_only(tmp_path: Path) -> None:
    _tree(tmp_path)
    first = kernel_sources_fingerprint(tmp_path)
    assert first == kernel_sources_fingerprint(tmp_path)  # deterministic
    (tmp_path / "offboard" / "daemon.py").write_text("x = 2\n")
    assert kernel_sources_fingerprint(tmp_path) == first  # no kernel there
    (tmp_path / "swarm_common" / "frames_kernel.py").write_text(
        "@kernel\ndef f(x):\n    return 2 * x\n"
    )
    changed = kernel_sources_fingerprint(tmp_path)
    assert changed != first  # the callee changed: every kernel's cache starts afresh
    (tmp_path / "offboard" / "new_kernel.py").write_text("@kernel\ndef h(x):\n    return x\n")
    assert kernel_sources_fingerprint(tmp_path) != changed
