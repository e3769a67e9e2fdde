"""Reading QP files (``.npz`` / ``.mat``) before anything is allocated: declared array shapes from the
file headers checked against the memory available, COO triplets and exported matrices validated, and
the exported parameters and defect maps checked (used by :meth:`dualfem.core.qp.QP.load`, the QP-file
problem and the VTK writer)."""
from __future__ import annotations

from pathlib import Path

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


def coo_from_arrays(d: dict, name: str, where: str, rows: int | None = None,
                    cols: int | None = None, against: str = "the length of F") -> sp.coo_matrix:
    """A sparse matrix from the COO arrays ``name_data``, ``name_row``, ``name_col``, ``name_shape`` of a file.

    Refused (InputError naming the array) before any allocation: non-integer indices or shape,
    a shape that disagrees with ``rows``/``cols`` (the sizes implied by the other arrays),
    arrays of unequal length, indices outside the shape, non-finite data, a shape too large for the
    memory (:func:`check_dims`: a 1 KB file may declare a 1e10 x 1e10 matrix). ``against`` names
    what fixes ``rows``/``cols`` in the message.
    """
    data, row, col, shape = (np.asarray(d[f"{name}_{s}"]).ravel() for s in ("data", "row", "col", "shape"))
    for s, a in (("row", row), ("col", col), ("shape", shape)):
        if a.dtype.kind not in "iu":
            raise InputError(f"array {name}_{s} in {where} must hold integers, got dtype {a.dtype}")
    if data.dtype.kind not in "iuf":
        raise InputError(f"array {name}_data in {where} must be numeric, got dtype {data.dtype}")
    if shape.size != 2 or shape.min() < 0:
        raise InputError(f"array {name}_shape in {where} must hold 2 sizes >= 0, got {shape.tolist()}")
    nr, nc = int(shape[0]), int(shape[1])
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
               "defect_front", "defect_front_id")


def check_maps(maps: dict, m: int, n_nodes: int | None, where: str, dim: int = 2) -> None:
    """The documented defect maps (``map_*`` arrays of an exported file; what post-processing and the
    VTK writer read), if present: shapes, dtypes and index ranges. InputError naming the array.

    ``defect_upper``/``defect_lower`` (m,) node ids in [0, n_nodes); ``defect_s`` (m,) finite;
    ``defect_id`` (m,) in [0, number of defects) (= len(defect_tips) / 2 when the tips are given);
    ``defect_tips`` (2 per defect,) node ids; ``defect_normals``/``defect_tangents`` (2, m) finite;
    ``normal``/``tangent`` (2,) finite. ``n_nodes``: the mesh's node count (None: not checked).
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
