"""Reports: render a study's results (rows, JSON, frozen solutions) into Markdown and figures, one
module per report kind. Render only: no solver runs here and nothing is imported from the cli; the
``dualfem report KIND`` commands (options, running the study) are :mod:`dualfem.cli.reports`."""
