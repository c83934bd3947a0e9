"""``ukemi`` command line: ``ukemi bench accuracy [--quick] [--out results/] ...``."""

from __future__ import annotations

import sys

USAGE = ("usage: ukemi bench accuracy [--quick] [--out DIR] [--sections LIST] "
         "[--update-benchmarks FILE]")


def main(argv: list[str] | None = None) -> int:
    """Dispatch ``bench <name> [options]``; returns the exit status."""
    args = sys.argv[1:] if argv is None else list(argv)
    if len(args) >= 2 and args[0] == "bench" and args[1] == "accuracy":
        from ukemi.bench import accuracy

        return accuracy.main(args[2:])
    print(USAGE, file=sys.stderr)
    return 0 if args[:1] in (["-h"], ["--help"]) else 2


if __name__ == "__main__":
    sys.exit(main())
