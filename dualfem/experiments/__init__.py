"""Experiments: the workspace (setup / update / solve of one scene), the runner, compare, bench and
stress sweeps, the harness they share, and every study a report shows (paper, convergence, figures,
plugins, robustness): the only code behind a report that runs solvers."""
