"""The backend registry (dualfem.numerics.factor): one interface for the direct factorizations and the AMG
K-solve: available()/missing(), factorize/solve with blocks of right-hand sides, the memory model."""
import numpy as np
import pytest
import scipy.sparse as sp

from dualfem.core.errors import InputError
from dualfem.numerics import factor as fb
from dualfem.numerics import memory


def _spd(n=60):
    A = sp.diags([-1.0, 2.05, -1.0], [-1, 0, 1], shape=(n, n)).tocsr()
    return A


def test_registry_lists_every_backend_and_keeps_factor_names_direct():
    assert fb.registered() == ["cudss", "pardiso", "cholmod", "superlu", "amg"]
    assert fb.names() == ["cudss", "pardiso", "cholmod", "superlu"] and "amg" not in fb.available()
    assert fb.registered(direct=False) == ["amg"]
    with pytest.raises(InputError, match="must be one of cudss, pardiso, cholmod, superlu"):
        fb.choose("amg")                     # factor= names a direct factorization only
    with pytest.raises(InputError, match="must be one of"):
        fb.backend_class("mumps")
    for name in fb.registered():
        cls = fb.backend_class(name)
        assert (cls.missing() is None) == bool(cls.available())
        if cls.missing() is not None:
            assert "install it with" in cls.missing()


def test_register_refuses_a_taken_name():
    class Fake(fb.Backend):
        name = "superlu"

        @classmethod
        def available(cls):
            return False

        def make(self, local=None, order=None):
            raise NotImplementedError

    with pytest.raises(ValueError, match="registered already"):
        fb.register(Fake)
    assert fb.backend_class("superlu") is not Fake


@pytest.mark.parametrize("name", ["superlu", "amg"])
def test_every_installed_backend_solves_a_block_of_right_hand_sides(name):
    cls = fb.backend_class(name)
    if cls.missing():
        pytest.skip(cls.missing())
    A = _spd()
    b = np.random.default_rng(0).standard_normal((A.shape[0], 3))
    f = (cls(rtol=1e-12) if name == "amg" else cls()).make().factorize(A)
    X = f.solve(b)
    assert X.shape == b.shape
    assert np.linalg.norm(A @ X - b) <= 1e-9 * np.linalg.norm(b)
    assert np.allclose(f.solve(b[:, 0]), X[:, 0], atol=1e-9)


def test_memory_model_is_the_backends_own():
    n = 100_000
    assert memory.factor_bytes(n, "amg") == memory.amg_bytes(n) == fb.backend_class("amg").peak_bytes(n, 3)
    assert memory.factor_bytes(n, "cholmod") == memory.factor_bytes(n, "pardiso")        # modelled as PARDISO
    assert memory.factor_bytes(n, "superlu") == fb.backend_class("superlu").peak_bytes(n) \
        == memory.direct_factor_bytes(n, "superlu")
    assert memory.estimate_peak_bytes(n, "amg") == max(memory.build_bytes(n)[0],
                                                       memory.build_bytes(n)[1] + memory.amg_bytes(n))
    with pytest.raises(InputError, match="backend"):
        memory.factor_bytes(n, "mumps")


def test_the_gpu_backend_is_registered_and_says_why_it_cannot_run(monkeypatch):
    """cuDSS (issue 39): registered and detected everywhere, never chosen while its device path is not
    written; its reason names what is missing here (modules, device, or the path) and the install line."""
    from dualfem.numerics.factor import cudss

    cls = fb.backend_class("cudss")
    assert cls is cudss.CudssBackend and cls.direct and not cls.available()
    assert "cudss" not in fb.available() and fb.get_default_unset() != "cudss"
    monkeypatch.setattr(cudss.importlib.util, "find_spec", lambda name: None)
    assert "nvmath-python and CuPy not installed" in cls.missing() and "dualfem[gpu]" in cls.missing()
    monkeypatch.setattr(cudss.importlib.util, "find_spec", lambda name: object())
    monkeypatch.setattr(cudss, "_device_count", lambda: 0)
    assert "no CUDA device" in cls.missing()
    monkeypatch.setattr(cudss, "_device_count", lambda: 1)
    assert "not written yet" in cls.missing()
    with pytest.raises(InputError, match=r"factor = 'cudss': cudss cannot run here: .*not written yet"):
        fb.choose("cudss")
    from dualfem.core.errors import MissingDependency

    with pytest.raises(MissingDependency, match="cudss cannot run here"):
        cls().make()


def test_factor_cudss_on_the_command_line_is_one_line(capsys):
    from dualfem.cli.main import main

    assert main(["solve", "f2", "--set", "N=8", "--factor", "cudss"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cudss cannot run here" in err[0] and "dualfem[gpu]" in err[0], err
