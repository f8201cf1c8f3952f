"""The design search, an internal family of :mod:`simulator.design` (no face of its own: its
names are offered by ``simulator.design``): the search file (``_spec``), the run of Optuna
trials as sweep points (``_run``), and its pictures, best design and page (``_report``)."""
