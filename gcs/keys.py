"""``gcs keys generate --out PATH``: a fresh MAVLink 2 signing key file.

The file holds 32 random bytes as 64 hexadecimal digits, mode 0600; a missing parent
directory is created with mode 0700. An existing file is refused unless ``--force``.
Bad paths exit 2 with one line. The key itself is never printed or logged.
(docs/security.md, "MAVLink signing and simulator link hygiene".)
"""

from __future__ import annotations

import argparse
import sys

from swarm_common.inputs import one_line
from swarm_common.signing import SigningKeyError, generate_key

EXIT_BAD_INPUT = 2


def cmd_keys_generate(args: argparse.Namespace) -> int:
    try:
        generate_key(args.out, overwrite=args.force)
    except SigningKeyError as exc:
        print(one_line(f"gcs keys generate: {exc}"), file=sys.stderr)  # a NUL in --out
        return EXIT_BAD_INPUT
    print(one_line(f"gcs keys generate: wrote a new signing key to {args.out} (mode 0600)"),
          file=sys.stderr)  # fmt: skip
    return 0


def add_keys_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``gcs keys generate``."""
    k = sub.add_parser("keys", help="MAVLink signing keys")
    ksub = k.add_subparsers(dest="keys_command", required=True)
    g = ksub.add_parser("generate", help="write a new 32-byte signing key file (mode 0600)")
    g.add_argument("--out", required=True, metavar="PATH", help="key file to create")
    g.add_argument("--force", action="store_true", help="replace an existing key file")
    g.set_defaults(func=cmd_keys_generate)
