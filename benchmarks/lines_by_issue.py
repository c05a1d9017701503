"""Net lines of ``src/`` since 2cc24ba, by the issue each change served (issue 29's goal: ``src/``
at least 2,000 lines shorter net of what other issues add).

    python benchmarks/lines_by_issue.py [REV]      # default REV: HEAD

Every first-parent commit from 2cc24ba to REV counts with its diff against its first parent
(a merge counts once, with its whole branch). Commits are assigned to an issue by the table
below (from their messages and branches); every commit not listed is issue 29's (the
simplification), including the restructure branches that also added issue 35's proofs.
"""

from __future__ import annotations

import subprocess
import sys

BASE = "2cc24ba"
OTHER = {
    35: "6182783 cb635e7 3740ac5 798aef6 c2ae480 d9e159f 110c6a0",  # proven rounding
    34: "1d89e2c",  # data integrity
    30: "dd906f3 7d20092 8f3dde8 958b3ce eb5920e 6571625 0e49be8 c53d5ac faefa67 af1fe54 f9c64f3 "
    "845f00d e52e395 e8d96b7 d420575 6788a6f 7423d57 b82b293",  # continuous-time, nonlinear
    31: "09cd69a f286dda d6c0bb4 03d1807 c59de05 bc97e12",  # the monitor on every model class
    32: "aadbbcc cb265bc cb9f293 f924cc5 f6715d8 a5bf917 ffee6c9 7d32c50 ec3e3e3 1ba2339 49927e5 "
    "86e477f",  # your own plant
    33: "62ed994 b57d3e5 4d87c10 bb7046d 0fd2b44 7fd6946 01a2338 05dd5a3 489b8c4 ba5128d",  # speed
}
SPLIT = {"9ffb5c8": (35, 313)}  # r-kkl2: its a-posteriori proof of the vectorised run (b1b0d48)
AMBIGUOUS = {"0894621": 35}  # the base margin's removal: issue 29's here, issue 35 also asked it


def git(*args: str) -> str:
    return subprocess.run(["git", *args], capture_output=True, text=True, check=True).stdout


def net(h: str) -> int:
    """Lines added minus deleted in ``src/`` by commit ``h`` against its first parent."""
    stat = git("diff", "--numstat", f"{h}^1", h, "--", "src")
    return sum(int(a) - int(d) for a, d, _ in (ln.split("\t") for ln in stat.splitlines()))


def main(rev: str = "HEAD") -> None:
    issue_of = {h: i for i, hs in OTHER.items() for h in hs.split()}
    by: dict[int, int] = {}
    print("net  commit   issue  subject")
    for h in git("log", "--first-parent", "--reverse", "--format=%h", f"{BASE}..{rev}").split():
        n = net(h)
        if n == 0:
            continue
        subject = git("log", "-1", "--format=%s", h).strip()[:90]
        if h in SPLIT:
            i, part = SPLIT[h]
            by[i] = by.get(i, 0) + part
            by[29] = by.get(29, 0) + n - part
            print(f"{n:5d} {h} {i}+29  {subject}")
            continue
        i = issue_of.get(h, 29)
        by[i] = by.get(i, 0) + n
        print(f"{n:5d} {h} {i:5d}  {subject}")
    print()
    for i in sorted(by):
        print(f"issue {i}: {by[i]:+d}")
    strict = by[29] - sum(net(h) for h in AMBIGUOUS)
    print(f"total: {sum(by.values()):+d}; issue 29 without {', '.join(AMBIGUOUS)}: {strict:+d}")


if __name__ == "__main__":
    main(*sys.argv[1:])
