"""Reproduce the figures of [Dinh2024] (Dinh & Tran, arXiv 2405.06445) with ivobs' ``kkl`` method.

A thin wrapper of :func:`ivobs.figures.generate` (same as
``ivobs figures --out DIR --paper Dinh2024``):

* Fig. 1 — Example 1, the random 8-state system, continuous time (``dinh2024_fig1_ct.png``, as
  in the paper) and discrete time (``dinh2024_fig1_dt.png``, ivobs' version);
* Fig. 4 — Example 2, the pendulum with a varying length (CT LTV), state ``x2``;
* Fig. 5 — Example 3, the discrete-time LTV system, state ``x2`` (bounds from ``k* = 2``);

each in the absence (top) and presence (bottom) of disturbances and noise. What ivobs chose
where the paper gives no value, and what differs: ``docs/figures.md``.

Run: ``python examples/dinh2024_figures.py OUTPUT_FOLDER``
"""

from __future__ import annotations

import sys

from ivobs.figures import generate


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print(__doc__)
        return 2
    for path in generate(argv[0], papers=["Dinh2024"]):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
