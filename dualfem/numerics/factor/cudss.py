"""NVIDIA cuDSS on a GPU (through nvmath-python's sparse direct solver): registration and detection.

What is here runs on every machine: the backend is registered (``--factor cudss`` and a solver's
``factor="cudss"`` name it, ``dualfem list``'s backends show it), and :meth:`CudssBackend.missing` says in
one sentence why it cannot run here: nvmath-python or CuPy not installed (with the install line of the
``gpu`` extra), no CUDA device, or a device and the libraries present but dualfem's GPU factorization
path not written yet. The device path (analysis once per sparsity pattern, a numeric factorization per
delta or Newton step, solves with blocks of right-hand sides, a memory model of the device) needs an
NVIDIA GPU to build and measure (issue 39); until it exists, :meth:`CudssBackend.available` is False, so
``auto`` never chooses this backend and no run ever reaches :meth:`CudssBackend.make`.
"""
from __future__ import annotations

import importlib.util

import numpy as np

from .base import Backend, Factorization, OrderHint

#: the Python modules the device path needs (import name -> what to install)
MODULES = {"nvmath": "nvmath-python", "cupy": "CuPy"}


def _device_count() -> int:
    """CUDA devices visible to CuPy (0 when the driver or the runtime is missing)."""
    try:
        import cupy

        return int(cupy.cuda.runtime.getDeviceCount())
    except Exception:  # noqa: BLE001 - no driver, no runtime, a broken install: no usable device
        return 0


class CudssBackend(Backend):
    """cuDSS sparse Cholesky on the GPU (not available yet: see the module docstring)."""

    name = "cudss"
    install_hint = "pip install 'dualfem[gpu]'  (nvmath-python with cuDSS and CuPy; an NVIDIA GPU, CUDA 12 driver)"
    memory_model = "pardiso"           # host memory: not modelled apart; the device's own model comes with the path

    @classmethod
    def why_not(cls) -> str:
        """Why the backend cannot run on this machine (never empty until the device path exists)."""
        absent = [what for mod, what in MODULES.items() if importlib.util.find_spec(mod) is None]
        if absent:
            return f"{' and '.join(absent)} not installed"
        if _device_count() == 0:
            return "no CUDA device is visible (CuPy found no GPU)"
        return ("a CUDA device and nvmath-python are here, but dualfem's cuDSS factorization path is not written "
                "yet (it needs a GPU to build and measure); use --factor pardiso, cholmod or superlu")

    @classmethod
    def available(cls) -> bool:
        return False

    @classmethod
    def missing(cls) -> str | None:
        return f"cudss cannot run here: {cls.why_not()}; install it with: {cls.install_hint}"

    def make(self, local: np.ndarray | None = None, order: OrderHint = None) -> Factorization:
        from dualfem.core.errors import MissingDependency

        raise MissingDependency(self.missing() or "cudss cannot run here")
