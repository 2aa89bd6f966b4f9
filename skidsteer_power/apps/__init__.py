"""The application layer: jobs that drive several layers below it (docs/EXTENDING.md, "Layers").

- :mod:`~skidsteer_power.apps.experiment_sets`: the main job (``make run``): the twin drives the
  chapter 7.3 experiment sets, the estimator validates its bags, the tables and figures;
- :mod:`~skidsteer_power.apps.fleet`: validation of many bags on Dask (``validate`` in fleet mode);
- :mod:`~skidsteer_power.apps.compare`: FESS against the baselines a user would fit (``compare``).

Only :mod:`skidsteer_power.cli` imports this package; nothing below it does (the import-linter
contracts in pyproject.toml, checked by ``make lint``).
"""
