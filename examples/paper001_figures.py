"""Reproduce Fig. 1 and Fig. 2 of paper 001 (Wang, Dinh, Zhang, Raïssi, Shen, IFAC 2020).

The example of Dinh et al. (2019) (scenario ``dinh2019``): x0 = (2.3, 1), u_k = (1, 1),
d_k = (sin k, sin k²), the fixed-time estimator with s = 2 and the optimal T of Theorem 1.
Fig. 1 shows the bounds of x1, Fig. 2 those of x2, with the true state.

The paper also draws the bounds of the method of Dinh et al. (2019) for comparison; that paper
is not among ivobs' sources, so its curves are not reproduced here.

Run: ``python examples/paper001_figures.py [output_dir]`` (writes ``paper001_fig1.png`` and
``paper001_fig2.png``, prints T and the widths).
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib
import numpy as np

import ivobs
from ivobs.plot import plot_estimates, save_figure


def main(out_dir: str = ".") -> None:
    matplotlib.use("Agg")  # files only, no display needed
    sc = ivobs.scenarios.get("dinh2019")
    traj = sc.simulate("paper")
    est = ivobs.make_estimator("fixed-time", sc.system, s=2)
    res = est.run(traj.u, traj.y)
    assert res.contains(traj.x).all()
    np.set_printoptions(precision=4, suppress=True)
    print("T (Theorem 1, eq. 13):")
    print(est.design.T)
    print("paper:")
    print(sc.reference["T"])
    print(f"boxes valid from k = {res.valid_from}; widths (constant, eq. 11): {res.mean_width()}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for i in (0, 1):
        fig = plot_estimates(
            {"fixed-time (001, s = 2)": res},
            truth=traj.x,
            states=[i],
            fill=False,
            title=f"Fig. {i + 1} of paper 001: x{i + 1} and its interval estimate",
        )
        path = out / f"paper001_fig{i + 1}.png"
        save_figure(fig, str(path))
        print(f"wrote {path}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
