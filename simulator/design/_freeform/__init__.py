"""Free-form design by gradients, an internal family of :mod:`simulator.design` (no face of
its own: its names are offered by ``simulator.design``): the design file (``_spec``), the
density and its projection (``_density``), the differentiable landscape (``_energy``), the
objective's terms (``_objectives``), the optimisation loop and its check (``_run``), and the
written pattern and page (``_report``)."""
