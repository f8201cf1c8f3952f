"""The calibration to a bench table, an internal family of :mod:`simulator.design` (no face
of its own: its names are offered by ``simulator.design``): the bench table (``_table``),
the fittable names (``_params``), the likelihood and the fit (``_fit``), and ``fitted.toml``
with the report (``_report``)."""
