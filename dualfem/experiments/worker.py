"""Process hygiene shared by the worker processes of ``dualfem bench`` and ``dualfem stress``."""
from __future__ import annotations


def volunteer_for_oom_killer() -> None:
    """Make this process the kernel's first choice when memory runs out (Linux; no-op elsewhere).

    A run that exhausts a shared machine's memory should lose its own worker, which the sweep
    records as a failed run, not the sweep's parent process or someone else's job.
    """
    try:
        with open("/proc/self/oom_score_adj", "w") as fh:
            fh.write("1000")
    except OSError:
        pass
