"""The moving-window exact hull of a time-invariant system, certified from cached multipliers.

The tightest box over a moving window of ``N`` steps is, per bound ``±x_i``, a linear program
([Tang2019, Section I]; :mod:`ivobs.estimators.exact`) whose constraint matrix does not change
with ``k`` for a time-invariant system: only its data do (``y``, ``u`` of the window and the
box of its first state, proven by this estimator ``N`` steps earlier). By weak duality, *any*
multipliers ``μ`` of the measurement rows give an upper bound that is affine in the data with
fixed coefficients (:mod:`.certificate`, identity (D)); the best one is the program's optimum.
So the estimator keeps, per bound, a small cache of multipliers (the duals of solves of the
window program by HiGHS, :mod:`.refresh`, at the start and every ``refresh`` steps), and at each
step evaluates all of them, two matrix products, and keeps the smallest certified value
[Neumaier2004]. The evaluation carries its floating-point error bound ([Higham2002, §3.1];
the γ terms of :mod:`.certificate`), so each bound holds in exact arithmetic whatever the
cache holds; it is the window's exact hull whenever the optimal multiplier is cached.

Layout: :mod:`.certificate` (the coefficients of a multiplier and the certified evaluation),
:mod:`.refresh` (the HiGHS model of the window program), :mod:`.auto` (the window chosen from
the model: how far back the program's optimal multipliers look), :mod:`.estimator` (the
estimator, its design and its state).
"""

from __future__ import annotations

from .estimator import DualWindow, DualWindowDesign, DualWindowState

__all__ = ["DualWindow", "DualWindowDesign", "DualWindowState"]
