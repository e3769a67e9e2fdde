"""Reading QP files (``.npz`` / ``.mat``) before anything is allocated: declared array shapes from the
file headers checked against the memory available, COO triplets and exported matrices validated, and
the exported parameters and defect maps checked (used by :meth:`dualfem.core.qp.QP.load`, the QP-file
problem and the VTK writer)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from dualfem.core.elasticity import PLANES
from dualfem.core.errors import InputError

#: bytes a QP needs per row and column of a matrix at the least (index pointers, the vectors of
#: that length and their copies in a solve): a declared shape is checked against the memory before
#: anything of that size is allocated
BYTES_PER_DIM = 128


def check_dims(what: str, dims: tuple[int, ...], where: str) -> None:
    """InputError naming ``what`` when a declared shape ``dims`` could not even be held in memory."""
    from dualfem.core.limits import check_alloc

    check_alloc(BYTES_PER_DIM * float(sum(int(x) for x in dims)), f"{what} in {where} declares shape "
                f"{tuple(int(x) for x in dims)}, which", "the file is corrupt or crafted, or needs a bigger machine")


def _npy_header(fh) -> tuple[tuple[int, ...], np.dtype]:
    from numpy.lib import format as npf

    version = npf.read_magic(fh)
    shape, _, dtype = (npf.read_array_header_1_0(fh) if version == (1, 0) else npf.read_array_header_2_0(fh))
    return tuple(int(x) for x in shape), dtype


def declared_arrays(path: Path) -> dict[str, tuple[tuple[int, ...], str]]:
    """Name -> (declared shape, kind) of every array of a .npz or .mat file, read from the headers
    alone (nothing decompressed): kind is the numpy dtype kind ("f", "i", "c", ...; "sparse" for a
    MATLAB sparse matrix, "?" when the header does not say)."""
    from dualfem.core.io import check_input_path

    check_input_path(path, "QP file")     # a FIFO or a device: refused before anything opens it
    out: dict[str, tuple[tuple[int, ...], str]] = {}
    if path.suffix == ".npz":
        import zipfile

        with zipfile.ZipFile(path) as z:
            for info in z.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                with z.open(info) as fh:
                    shape, dtype = _npy_header(fh)
                out[info.filename[:-4]] = (shape, dtype.kind if dtype.fields is None else "V")
    else:
        import scipy.io

        for name, shape, cls in scipy.io.whosmat(path):
            out[name] = (tuple(int(x) for x in shape), "sparse" if cls == "sparse" else "?")
    return out


def _itemsize(kind: str) -> int:
    return 16 if kind == "c" else 8


def read_arrays(path: Path, where: str) -> dict:
    """Every array of a QP file (.npz or .mat), validated before and after loading.

    Before anything is decompressed: the declared shapes of the file's headers must fit in the memory
    available (a 1 KB file may declare a 1e10 x 1e10 dense array). After: no complex array (a complex
    matrix must not be read as its real part), no object or string array where numbers are expected
    (checked by the callers).
    """
    try:
        decl = declared_arrays(path)
    except NotImplementedError:         # MATLAB v7.3: the callers say how to save it
        raise
    except Exception as exc:  # noqa: BLE001 - a corrupt or crafted header: one line, no traceback
        raise InputError(f"cannot read QP file {str(path)!r}: {type(exc).__name__}: {exc}") from None
    total = 0.0
    biggest: tuple[str, tuple[int, ...], float] = ("", (), 0.0)
    for name, (shape, kind) in decl.items():
        size = float(np.prod([float(x) for x in shape])) if kind != "sparse" else float(sum(shape))
        nbytes = size * _itemsize(kind)
        total += nbytes
        if nbytes >= biggest[2]:
            biggest = (name, shape, nbytes)
        if kind == "c":
            raise InputError(f"array {name!r} in {where} holds complex numbers: a QP's data must be real")
    from dualfem.core.limits import check_alloc

    check_alloc(3 * total, f"{where} (its largest array {biggest[0]!r} declares shape {biggest[1]})",
                "the file is corrupt or crafted, or needs a bigger machine")
    if path.suffix == ".npz":
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
    else:
        import scipy.io

        d = {k: v for k, v in scipy.io.loadmat(path).items() if not k.startswith("__")}
    for name, a in d.items():
        kind = a.dtype.kind if hasattr(a, "dtype") else "?"
        if kind == "c":
            raise InputError(f"array {name!r} in {where} holds complex numbers: a QP's data must be real")
    return d


def _sparse_arrays(d: dict, name: str, where: str, index_parts: tuple[str, str]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]:
    """``name_data``, the two integer index arrays ``name_<part>`` and the declared ``name_shape`` of a
    sparse matrix stored as arrays, flattened; InputError naming the array for a non-integer index or
    shape, non-numeric data or a shape that is not two sizes >= 0."""
    data, a, b, shape = (np.asarray(d[f"{name}_{s}"]).ravel() for s in ("data", *index_parts, "shape"))
    for s, arr in ((index_parts[0], a), (index_parts[1], b), ("shape", shape)):
        if arr.dtype.kind not in "iu":
            raise InputError(f"array {name}_{s} in {where} must hold integers, got dtype {arr.dtype}")
    if data.dtype.kind not in "iuf":
        raise InputError(f"array {name}_data in {where} must be numeric, got dtype {data.dtype}")
    if shape.size != 2 or shape.min() < 0:
        raise InputError(f"array {name}_shape in {where} must hold 2 sizes >= 0, got {shape.tolist()}")
    return data, a, b, (int(shape[0]), int(shape[1]))


def coo_from_arrays(d: dict, name: str, where: str, rows: int | None = None,
                    cols: int | None = None, against: str = "the length of F") -> sp.coo_matrix:
    """A sparse matrix from the COO arrays ``name_data``, ``name_row``, ``name_col``, ``name_shape`` of a file.

    Refused (InputError naming the array) before any allocation: non-integer indices or shape,
    a shape that disagrees with ``rows``/``cols`` (the sizes implied by the other arrays),
    arrays of unequal length, indices outside the shape, non-finite data, a shape too large for the
    memory (:func:`check_dims`: a 1 KB file may declare a 1e10 x 1e10 matrix). ``against`` names
    what fixes ``rows``/``cols`` in the message.
    """
    data, row, col, (nr, nc) = _sparse_arrays(d, name, where, ("row", "col"))
    if rows is not None and rows == cols and nr != nc:
        raise InputError(f"{name} must be square, but {name}_shape in {where} declares ({nr}, {nc})")
    for want, got, what in ((rows, nr, "rows"), (cols, nc, "columns")):
        if want is not None and got != want:
            raise InputError(f"{name} must have {want} {what} ({against}), but {name}_shape in {where} "
                             f"declares {got}")
    if not (data.size == row.size == col.size):
        raise InputError(f"{name}_data, {name}_row, {name}_col in {where} must have equal lengths, "
                         f"got {data.size}, {row.size}, {col.size}")
    if row.size and (row.min() < 0 or row.max() >= nr or col.min() < 0 or col.max() >= nc):
        raise InputError(f"{name}_row/{name}_col in {where} hold indices outside {name}_shape = ({nr}, {nc})")
    check_dims(f"{name}_shape", (nr, nc), where)       # no other array fixes this size: the memory does
    return sp.coo_matrix((data.astype(float), (row.astype(np.int64), col.astype(np.int64))), shape=(nr, nc))


def csc_from_arrays(d: dict, name: str, where: str, rows: int | None = None,
                    cols: int | None = None) -> sp.csc_matrix:
    """A sparse matrix from scipy's CSC arrays ``name_data``, ``name_indices``, ``name_indptr``, ``name_shape``.

    Refused (InputError naming the array) before any allocation: non-integer indices or shape, a shape
    that disagrees with ``rows``/``cols`` or does not fit in memory, an ``indptr`` that is not
    ``cols + 1`` non-decreasing offsets from 0 to the number of entries, row indices outside the shape,
    non-finite data."""
    data, ind, ptr, (nr, nc) = _sparse_arrays(d, name, where, ("indices", "indptr"))
    for want, got, what in ((rows, nr, "rows"), (cols, nc, "columns")):
        if want is not None and got != want:
            raise InputError(f"{name} must have {want} {what} (the length of q), but {name}_shape in {where} "
                             f"declares {got}")
    check_dims(f"{name}_shape", (nr, nc), where)
    if ptr.size != nc + 1 or ptr[0] != 0 or ptr[-1] != data.size or np.any(np.diff(ptr) < 0) or ind.size != data.size:
        raise InputError(f"{name}_indptr/{name}_indices in {where} are not CSC arrays of {name}_shape = ({nr}, {nc}) "
                         f"with {data.size} entries")
    if ind.size and (ind.min() < 0 or ind.max() >= nr):
        raise InputError(f"{name}_indices in {where} hold row indices outside {name}_shape = ({nr}, {nc})")
    if not np.all(np.isfinite(data)):
        raise InputError(f"array {name}_data in {where} contains NaN or infinite entries")
    return sp.csc_matrix((data.astype(float), ind.astype(np.int64), ptr.astype(np.int64)), shape=(nr, nc))


def export_matrix(d: dict, name: str, where: str, rows: int | None, cols: int) -> sp.spmatrix:
    """K or B of an exported file: COO triplets ``name_*`` (checked before allocating) and/or, in a
    .mat file, the sparse matrix ``name``; both present must be the same matrix (else ambiguous)."""
    triplets = any(f"{name}_{s}" in d for s in ("data", "row", "col", "shape"))
    coo = coo_from_arrays(d, name, where, rows=rows, cols=cols) if triplets or name not in d else None
    if name not in d:
        return coo
    M = d[name]
    if not sp.issparse(M):
        raise InputError(f"array {name!r} in {where} must be a sparse matrix (or give the triplets {name}_data, "
                         f"{name}_row, {name}_col, {name}_shape)")
    if M.dtype.kind not in "biuf":
        raise InputError(f"array {name!r} in {where} must be real numbers, got dtype {M.dtype}")
    want = (rows if rows is not None else M.shape[0], cols)
    if M.shape != want:
        raise InputError(f"{name} in {where} must have shape {want}, got {M.shape}")
    check_dims(name, M.shape, where)
    if coo is not None and (coo.shape != M.shape or (sp.csr_matrix(coo, dtype=float)
                                                     - sp.csr_matrix(M, dtype=float)).count_nonzero()):
        raise InputError(f"{where} holds both the matrix {name!r} and the triplets {name}_data/{name}_row/"
                         f"{name}_col/{name}_shape, and they differ: ambiguous, keep one")
    return M


def check_params(params: dict, where: str) -> None:
    """Material and model parameters read from a file, validated like scene parameters."""

    def number(k: str) -> float | None:
        v = params.get(k)
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not np.isfinite(v):
            raise InputError(f"param_{k} in {where} must be a finite number, got {v!r}")
        return float(v)

    for k in ("E", "delta", "width", "height"):
        v = number(k)
        if v is not None and v <= 0:
            raise InputError(f"param_{k} in {where} must be > 0, got {v!r}")
    nu = number("nu")
    if nu is not None and not -1.0 < nu < 0.5:
        raise InputError(f"param_nu in {where} must lie in (-1, 0.5), got {nu!r}")
    if "plane" in params and params["plane"] not in PLANES:
        raise InputError(f"param_plane in {where} must be one of {', '.join(PLANES)}, got {params['plane']!r}")


#: the documented maps that are vectors (a .mat file stores them as 1 x k)
VECTOR_MAPS = ("defect_upper", "defect_lower", "defect_s", "defect_id", "defect_tips", "normal", "tangent",
               "defect_front", "defect_front_id", "defect_delta")


def check_maps(maps: dict, m: int, n_nodes: int | None, where: str, dim: int = 2) -> None:
    """The documented defect maps (``map_*`` arrays of an exported file; what post-processing and the
    VTK writer read), if present: shapes, dtypes and index ranges. InputError naming the array.

    ``defect_upper``/``defect_lower`` (m,) node ids in [0, n_nodes); ``defect_s`` (m,) finite;
    ``defect_id`` (m,) in [0, number of defects) (= len(defect_tips) / 2 when the tips are given);
    ``defect_tips`` (2 per defect,) node ids; ``defect_normals``/``defect_tangents`` (2, m) finite;
    ``normal``/``tangent`` (2,) finite; ``defect_delta`` (m,) > 0. ``n_nodes``: the mesh's node count (None:
    not checked).
    With ``dim = 3`` (a 3D mesh): ``defect_normals`` (m, 3) finite, ``defect_front`` (k,) node ids and
    ``defect_front_id`` (k,) defect numbers (one per front node), ``defect_faces`` (3, n_faces) node ids
    of the defect surfaces' triangles on the "-" face (output: VTK, figures).
    """

    def arr(k: str, kinds: str, shape: tuple) -> np.ndarray | None:
        if k not in maps:
            return None
        a = np.asarray(maps[k])
        if a.dtype.kind not in kinds:
            want = "integers" if kinds == "iu" else "real numbers"
            raise InputError(f"map {k!r} of {where} must hold {want}, got dtype {a.dtype}")
        if a.shape != shape and not (shape == (-1,) and a.ndim == 1):
            raise InputError(f"map {k!r} of {where} must have shape {shape}, got {a.shape}")
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise InputError(f"map {k!r} of {where} contains NaN or infinite entries")
        return a

    def nodes(k: str, a: np.ndarray | None) -> None:
        if a is not None and a.size and (a.min() < 0 or (n_nodes is not None and a.max() >= n_nodes)):
            rng = f"[0, {n_nodes})" if n_nodes is not None else ">= 0"
            raise InputError(f"map {k!r} of {where} must hold node ids in {rng} (the mesh's nodes), "
                             f"got values in [{a.min()}, {a.max()}]")

    for k in ("defect_upper", "defect_lower"):
        nodes(k, arr(k, "iu", (m,)))
    arr("defect_s", "iuf", (m,))
    delta = arr("defect_delta", "iuf", (m,))
    if delta is not None and delta.size and delta.min() <= 0:
        raise InputError(f"map 'defect_delta' of {where} must be > 0, got {delta.min()!r}")
    tips = arr("defect_tips", "iu", (-1,))
    nodes("defect_tips", tips)
    if tips is not None and tips.size % 2:
        raise InputError(f"map 'defect_tips' of {where} must hold 2 node ids per defect, got {tips.size}")
    ids = arr("defect_id", "iu", (m,))
    ndef = tips.size // 2 if tips is not None else m
    if ids is not None and ids.size and (ids.min() < 0 or ids.max() >= max(ndef, 1)):
        raise InputError(f"map 'defect_id' of {where} must hold defect numbers in [0, {max(ndef, 1)})"
                         f"{' (2 tips per defect in defect_tips)' if tips is not None else ''}, "
                         f"got values in [{ids.min()}, {ids.max()}]")
    if dim == 3:
        arr("defect_normals", "iuf", (m, 3))
        front = arr("defect_front", "iu", (-1,))
        nodes("defect_front", front)
        fid = arr("defect_front_id", "iu", (-1,))
        if (front is None) != (fid is None) or (front is not None and fid is not None and front.size != fid.size):
            raise InputError(f"maps 'defect_front' and 'defect_front_id' of {where} must be given together, "
                             f"of equal lengths")
        faces = arr("defect_faces", "iu", (3, np.asarray(maps.get("defect_faces", np.zeros((3, 0)))).shape[-1]))
        nodes("defect_faces", faces)
        return
    for k in ("defect_normals", "defect_tangents"):
        arr(k, "iuf", (2, m))
    for k in ("normal", "tangent"):
        arr(k, "iuf", (2,))


# ------------------------------------------------------------------ the two conventions of a QP file
#: the ecosystem's names (qpsolvers, OSQP, Clarabel, ...): P, q, G, h, A, b, lb, ub
QPSOLVERS_NAMES = ("P", "q", "G", "h", "A", "b", "lb", "ub")
#: dualfem's own names: K, F, B, Bx_min (``dualfem export`` writes K, F, B: Bx_min = 0)
OWN_NAMES = ("K", "F", "B", "Bx_min")
#: what each convention's arrays mean (for messages and docs/export.md)
CONVENTIONS = {
    "qpsolvers": "qpsolvers' convention: minimize 1/2 x'Px + q'x subject to G x <= h, A x = b, lb <= x <= ub",
    "dualfem": "dualfem's own convention: minimize 1/2 x'Kx - F'x subject to B x >= Bx_min (Bx_min omitted: 0)",
}
_MATRICES = ("P", "G", "A", "K", "B")
_TRIPLET = ("data", "row", "col", "shape", "indices", "indptr")


def base_names(d: dict) -> set[str]:
    """The QP names a file's arrays stand for: a matrix given as COO triplets or CSC arrays (``P_data``, ...)
    counts as ``P``."""
    out = set()
    for k in d:
        head, _, tail = k.rpartition("_")
        out.add(head if head in _MATRICES and tail in _TRIPLET else k)
    return out


def convention(d: dict, where: str) -> str:
    """``"qpsolvers"`` or ``"dualfem"``: the convention a QP file's array names declare (:data:`CONVENTIONS`).

    Refused (InputError naming both conventions): a file holding names of both (it could be read either
    way: qpsolvers' ``G x <= h`` or dualfem's ``B x >= Bx_min``), of neither, or an optional string array
    ``convention`` that does not start with the convention its names declare.
    """
    names = base_names(d)
    ours, theirs = [k for k in OWN_NAMES if k in names], [k for k in QPSOLVERS_NAMES if k in names]
    both = f"{CONVENTIONS['qpsolvers']} (arrays {', '.join(QPSOLVERS_NAMES)}); {CONVENTIONS['dualfem']} (arrays " \
           f"{', '.join(OWN_NAMES)}; what dualfem export writes)"
    if ours and theirs:
        raise InputError(f"{where} holds both an exported QP or dualfem's own arrays ({', '.join(ours)}) and the "
                         f"arrays {', '.join(theirs)} of qpsolvers' convention: ambiguous, keep one convention. "
                         f"The two: {both}")
    if not ours and not theirs:
        raise InputError(f"{where} holds no QP: write the arrays of one convention: {both}")
    found = "dualfem" if ours else "qpsolvers"
    if "convention" in d:
        said = str(np.asarray(d["convention"]).ravel()[0]) if np.size(d["convention"]) else ""
        if not said.strip().lower().startswith(found):
            raise InputError(f"{where} says convention = {said!r}, but its arrays ({', '.join(ours or theirs)}) are "
                             f"those of {CONVENTIONS[found]}: ambiguous, fix one")
    return found


def qpsolvers_arrays(qp) -> dict[str, np.ndarray]:
    """A QP in qpsolvers' names (``dualfem export --convention qpsolvers``): ``P = K``, ``q = -F``,
    ``G = -B``, ``h = 0`` as COO triplets ``P_*``, ``G_*`` (0-based) and vectors, plus ``convention``
    (:data:`CONVENTIONS`) and ``name``. A shifted QP (``qp.shift``: a QP file's ``h != 0``) is written in
    its user's unknowns ``y = x + shift.x``: ``q = -shift.load`` (else ``-(F + K shift.x)``) and
    ``h = -shift.rhs`` (else ``-B shift.x``)."""
    P, G = sp.coo_matrix(qp.K), sp.coo_matrix(-qp.B)
    q, h = -np.asarray(qp.F, dtype=float), np.zeros(qp.m)
    s = qp.shift
    if s is not None:
        q = -(s.load if s.load is not None else qp.F + qp.K @ s.x)
        h = -(s.rhs if s.rhs is not None else qp.B @ s.x)
    return {"P_data": P.data, "P_row": P.row, "P_col": P.col, "P_shape": np.array(P.shape),
            "G_data": G.data, "G_row": G.row, "G_col": G.col, "G_shape": np.array(G.shape),
            "q": q, "h": h, "convention": np.array(CONVENTIONS["qpsolvers"]), "name": np.array(qp.name)}


def save_arrays(path: str | Path, arrays: dict[str, Any]) -> Path:
    """Write the arrays of :func:`qpsolvers_arrays` atomically: ``.npz`` as given (COO triplets); ``.mat``
    with the matrices as MATLAB sparse matrices ``P``, ``G`` (1-based in MATLAB) instead of triplets."""
    from dualfem.core.io import atomic_write

    path = Path(path)
    if path.suffix == ".npz":
        def write(tmp: str) -> None:
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, **arrays)
    elif path.suffix == ".mat":
        import scipy.io

        mat = {k: v for k, v in arrays.items() if k.rpartition("_")[0] not in _MATRICES}
        for name in ("P", "G"):
            if f"{name}_data" in arrays:
                mat[name] = sp.csc_matrix(coo_from_arrays(arrays, name, str(path)))

        def write(tmp: str) -> None:
            scipy.io.savemat(tmp, mat, do_compression=True)
    else:
        raise InputError(f"output file must end in .npz or .mat, got {path.name!r}")
    return atomic_write(path, write)
