"""The swing: what every generator (the RL policy of jaxexo.inference, CFFTG of jaxexo.baselines) does
with the heel path it plans, NumPy only.

``options`` (the one checked record of a swing's options, and its scenes), ``smoothing`` (the
smoothing spline), ``clearing`` (lifting a smoothed curve clear of the obstacle), ``finish`` (the RL
path's smoothing, clearing and landing), ``trajectory`` (the checked trajectory and its records),
``time_law``, ``curve_check`` and ``timing`` (the swing timed at the device's limits), ``export`` (CSV and JSON).

Nothing is imported here: each module is loaded where it is used, which keeps ``import
jaxexo.inference`` fast.
"""
