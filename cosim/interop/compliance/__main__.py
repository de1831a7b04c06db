"""``python -m cosim.interop.compliance FMU...``: report on each FMU, exit 1 on an error."""

from __future__ import annotations

import sys

from cosim.interop.compliance import check_fmu, format_report, passed


def _main(argv: list[str]) -> int:
    failed = False
    for p in argv:
        problems = check_fmu(p)
        print(format_report(p, problems))
        failed |= not passed(problems)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
