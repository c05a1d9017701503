"""The methods for nonlinear systems (:class:`~ivobs.NonlinearSystem`, or a linear system taken
as one), one module each, and what they share:

* :mod:`.interval`: ``nl-interval``, inclusion functions and contractors ([Jaulin2001],
  [Moore2009]);
* :mod:`.zonotope`: ``nl-zonotope``, a zonotopic filter by conservative linearisation with
  strips ([Alamo2005], [Althoff2008], [Rego2020]);
* :mod:`.meanvalue`: the measurement as an interval, the mean-value form of a map over a box,
  one step back through the model.

The models' guaranteed interval code (generated from their expressions, rounded outward) is in
:mod:`ivobs.model.nonlinear`; docs/nonlinear.md and docs/nonlinear_sets.md.
"""
