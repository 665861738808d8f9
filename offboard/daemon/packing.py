"""The ``--agents`` text of a packed daemon process: parse and format (no imports of the
daemon itself, so the ground station's launcher can use it cheaply)."""

from __future__ import annotations

MAX_AGENTS_ARG = 1000  # an --agents list longer than this is a typo


def parse_agents(text: str) -> list[int]:
    """``--agents``: ``3-8`` (a range), ``1,2,5`` (a list) or both (``1-3,7``): the ids in
    the order given, each once. Raises ValueError with a one-line reason."""
    ids: list[int] = []
    for part in text.split(","):
        lo_s, dash, hi_s = part.strip().partition("-")
        try:
            lo = int(lo_s)
            hi = int(hi_s) if dash else lo
        except ValueError:
            raise ValueError(f"{part.strip()!r} is not an id or a range A-B") from None
        if lo < 1 or hi < lo or hi - lo >= MAX_AGENTS_ARG:
            raise ValueError(f"{part.strip()!r}: ids are >= 1 and a range A-B has A <= B")
        ids += [i for i in range(lo, hi + 1) if i not in ids]
    if not ids:
        raise ValueError("no agent id")
    return ids


def format_agents(ids: list[int]) -> str:
    """The shortest ``--agents`` text for ``ids``: ``3-8`` when contiguous, else a list."""
    if len(ids) > 1 and ids == list(range(ids[0], ids[-1] + 1)):
        return f"{ids[0]}-{ids[-1]}"
    return ",".join(str(i) for i in ids)
