"""Bags against the model: validate a recording with the estimator, online and from the command.

Reading and writing the files is :mod:`skidsteer_power.bag_io`, a layer below; this package is the
analysis above the estimator: per-segment and whole-run comparisons (:mod:`.validate`,
:mod:`.validate_metrics`), the estimator run online over a bag (:mod:`.online`), how long a
recorded command holds (:mod:`.cmd_timing`) and the report (:mod:`.report`).
"""
