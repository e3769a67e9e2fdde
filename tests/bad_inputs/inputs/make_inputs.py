"""Writes the crafted files of cases_inputs.toml (run from this folder: python make_inputs.py).

Each is what a hostile user would hand-craft in a few lines of numpy: declared sizes that the data
do not back, complex data, two spellings of one matrix, crafted export maps.
"""
from __future__ import annotations

import io
import zipfile

import numpy as np
import scipy.io
import scipy.sparse as sp
from numpy.lib import format as npf


def header_only(path: str, name: str, shape: tuple) -> None:
    """Append an .npy member whose header declares ``shape`` (float64) and that holds no data."""
    buf = io.BytesIO()
    npf.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": shape})
    with zipfile.ZipFile(path, "a") as z:
        z.writestr(name + ".npy", buf.getvalue())


def export_f2() -> dict:
    from dualfem.core.scene import load_scene

    return load_scene("f2", {"N": 8}).build().to_dict()


# P as triplets declaring 3e9 x 3e9 beside a q of length 3
np.savez("letters_huge_P.npz", P_data=np.ones(3), P_row=np.arange(3), P_col=np.arange(3),
         P_shape=np.array([3 * 10**9, 3 * 10**9]), q=np.zeros(3), G=np.eye(3))
# G as triplets declaring 1e12 rows (nothing else fixes the row count)
np.savez("letters_G_rows.npz", P=np.eye(3), q=-np.ones(3), G_data=np.ones(1), G_row=np.zeros(1, int),
         G_col=np.zeros(1, int), G_shape=np.array([10**12, 3]))
# a dense P whose header declares 2e5 x 2e5 (320 GB) and holds nothing
np.savez("dense_header_bomb.npz", q=np.zeros(3), G=np.eye(3))
header_only("dense_header_bomb.npz", "P", (200_000, 200_000))
# complex data: a sparse G in a .mat, q in an .npz, weights of an exported file
scipy.io.savemat("complex_G.mat", {"P": np.eye(2), "q": -np.ones(2), "G": sp.csc_matrix(np.eye(2) * (1 - 2j))})
np.savez("complex_q.npz", P=np.eye(2), q=np.array([1 + 0j, -1 + 1e-9j]), G=np.eye(2))
d = export_f2()
np.savez_compressed("complex_weights.npz", **{**d, "weights": d["weights"] + 1e-12j})
# G given twice: dense and as triplets that differ
np.savez("G_twice.npz", P=np.eye(2), q=-np.ones(2), G=np.eye(2), G_data=np.array([-1.0, -1.0]),
         G_row=np.arange(2), G_col=np.arange(2), G_shape=np.array([2, 2]))
# no unknowns; no constraints
np.savez("no_unknowns.npz", P=np.zeros((0, 0)), q=np.zeros(0), G=np.zeros((0, 0)))
np.savez("no_constraints.npz", P=np.array([[2.0, 0.5], [0.5, 1.0]]), q=np.array([-1.0, 1.0]), G=np.zeros((0, 2)))
# crafted export maps
np.savez_compressed("map_defect_id.npz", **{**d, "map_defect_id": np.full_like(d["map_defect_id"], 10**15)})
np.savez_compressed("map_upper_oob.npz", **{**d, "map_defect_upper": d["map_defect_upper"] - 10**6})
np.savez_compressed("map_node_dofs_1row.npz", **{**d, "map_node_dofs": d["map_node_dofs"][1:]})
np.savez_compressed("map_normals_short.npz", **{**d, "map_defect_normals": d["map_defect_normals"][:, :1]})
# an exported QP (K, F, B) with a q beside it: which objective is meant?
np.savez_compressed("export_and_letters.npz", **d, q=-d["F"])
