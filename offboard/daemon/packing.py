"""The ``--agents`` text of a packed daemon process: parse and format (no imports of the
daemon itself, so the ground station's launcher can use it cheaply)."""

from __future__ import annotations

MAX_AGENTS_ARG = 1000  # an --agents list longer than this is a typo
SHOWN_IDS = 8  # ids an error lists before it gives only their count
SHOWN_CHARS = 40  # characters of an --agents text an error quotes


def brief_ids(ids: list[int]) -> str:
    """``ids`` as an error shows them: a short list whole, a long one (``--agents 1-300``:
    292 unknown ids) as its first :data:`SHOWN_IDS` and the count, so the line stays short."""
    if len(ids) <= SHOWN_IDS:
        return str(ids)
    return f"[{', '.join(str(i) for i in ids[:SHOWN_IDS])}, ... ({len(ids)} ids)]"


def brief_text(text: str) -> str:
    """``repr(text)`` of a user's ``--agents`` text, cut to about :data:`SHOWN_CHARS`."""
    return repr(text) if len(text) <= SHOWN_CHARS else f"{text[:SHOWN_CHARS - 3]!r}..."


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
            raise ValueError(f"{brief_text(part.strip())} is not an id or a range A-B") from None
        if lo < 1 or hi < lo or hi - lo >= MAX_AGENTS_ARG:
            raise ValueError(f"{brief_text(part.strip())}: ids are >= 1 and a range A-B has "
                             "A <= B")
        ids += [i for i in range(lo, hi + 1) if i not in ids]
    if not ids:
        raise ValueError("no agent id")
    return ids


def format_agents(ids: list[int]) -> str:
    """The shortest ``--agents`` text for ``ids``: ``3-8`` when contiguous, else a list."""
    if len(ids) > 1 and ids == list(range(ids[0], ids[-1] + 1)):
        return f"{ids[0]}-{ids[-1]}"
    return ",".join(str(i) for i in ids)
