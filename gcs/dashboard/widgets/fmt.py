"""Number formatting shared by the widgets (fixed widths, '-' for unknown)."""

from __future__ import annotations


def num(x: float | None, width: int = 5, prec: int = 2) -> str:
    if x is None:
        return "-".rjust(width)
    s = f"{x:.{prec}f}"
    if len(s) > width:
        s = f"{x:.{max(0, prec - (len(s) - width))}f}"
    return s.rjust(width)


def vec(v: tuple[float, float, float] | None, width: int = 5, prec: int = 1) -> str:
    if v is None:
        return " ".join(["-".rjust(width)] * 3)
    return " ".join(num(c, width, prec) for c in v)


def age(a: float | None) -> str:
    if a is None:
        return "never"
    if a < 10:
        return f"{a:.1f}s"
    if a < 600:
        return f"{a:.0f}s"
    return f"{a / 60:.0f}m"


SEVERITY_STYLE = {
    0: "bold white on red",
    1: "bold white on red",
    2: "bold red",
    3: "red",
    4: "yellow",
    5: "cyan",
    6: "",
    7: "dim",
}
SEVERITY_TAG = ["EMERG", "ALERT", "CRIT", "ERROR", "WARN", "NOTE", "INFO", "DEBUG"]
