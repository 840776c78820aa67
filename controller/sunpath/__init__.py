"""Sun-path filter: the seed paper's parabola method and a physical Kalman model.

Modules: :mod:`.ephemeris` (SPA geocentric sun, spherical astronomy), :mod:`.parabola`
(paper's method), :mod:`.mirror` (samples balanced about noon), :mod:`.localisation`
(noon formulas), :mod:`.kalman` (the EKF), :mod:`.batch` (the EKF over a batch of observations), :mod:`.kalman_config` (its state layout, tuning
and records), :mod:`.orbit` (orbit law), :mod:`.initial_fit` (starting the filter),
:mod:`.persistence` (the filter as a dict), :mod:`.policy` (observed / predicted /
ephemeris estimate), :mod:`.state` (atomic state file), :mod:`.io` (CSV), :mod:`.days`
(day grouping and result rows).  See docs/sunpath.md.
"""
