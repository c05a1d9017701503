"""Reproduce Fig. 1 and Fig. 2 of [Wang2020] (Wang, Dinh, Zhang, Raïssi, Shen, IFAC 2020).

A thin wrapper of :func:`ivobs.figures.generate` (same as
``ivobs figures --out DIR --paper Wang2020``): the example of [Dinh2019] (scenario ``dinh2019``),
the fixed-time estimator with s = 2 and the T of Theorem 1, bounds of x1 (Fig. 1) and x2
(Fig. 2) with the true state. The paper's comparison curves (the method of Dinh et al. 2019) are
not drawn: that paper is not among ivobs' sources. See ``docs/figures.md``.

Run: ``python examples/wang2020_figures.py [output_dir]`` (writes ``wang2020_fig1.png`` and
``wang2020_fig2.png``, prints T next to the paper's).
"""

from __future__ import annotations

import sys

import numpy as np

import ivobs
from ivobs.figures import generate


def main(out_dir: str = ".") -> None:
    sc = ivobs.scenarios.get("dinh2019")
    est = ivobs.make_estimator("fixed-time", sc.system, s=sc.reference["s"])
    np.set_printoptions(precision=4, suppress=True)
    print(f"T (Theorem 1, eq. 13):\n{est.design.T}\npaper:\n{sc.reference['T']}")
    for path in generate(out_dir, papers=["Wang2020"]):
        print(f"wrote {path}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
