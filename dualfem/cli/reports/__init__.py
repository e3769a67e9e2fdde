"""The ``dualfem report KIND`` commands, one module per kind: each parses its arguments, runs the
study through :mod:`dualfem.experiments` (or reads the results a study wrote), then calls the
renderer of :mod:`dualfem.reports`, and registers itself with :func:`dualfem.cli.report.register_report`."""
