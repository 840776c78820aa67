"""Sun-path filter: the seed paper's parabola priors and a physical Kalman model.

Modules: :mod:`.ephemeris` (SPA geocentric sun, spherical astronomy), :mod:`.parabola`
(paper's method), :mod:`.localisation` (noon formulas), :mod:`.kalman` (EKF),
:mod:`.policy` (observed / predicted / ephemeris estimate), :mod:`.state` (persistence),
:mod:`.io` (CSV), :mod:`.days` (day grouping and result rows).  See docs/sunpath.md.
"""
