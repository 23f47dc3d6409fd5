"""Symmetric CSR matrices from element entries: pairwise sums and a placed mirror.

The element loop gives the strict upper triangle batch by batch. Adding the batches one
after another re-merged the growing sum every time, and ``U + U^T + diag`` took two more
full merges: on P2 at 64^3 (21 million upper entries in 7 batches) those additions took
as long as the element arithmetic and the COO conversions together. Here the batches are
added pairwise and the symmetric matrix is laid out directly: row i is row i of ``U^T``
(columns below i, from one CSR/CSC transpose, a linear counting sort), the diagonal, then
row i of ``U``, each already sorted, so the result is canonical without an addition.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

__all__ = ["sum_pairwise", "symmetric_from_upper"]


def _index(n: int) -> type:
    return np.int32 if n < 2 ** 31 - 1 else np.int64


def sum_pairwise(parts: list[sparse.csr_matrix]) -> sparse.csr_matrix:
    """The sum of equally shaped CSR matrices, added pairwise (a balanced tree).

    Adding them one after another re-merges the growing sum every time (quadratic in
    the number of parts); pairwise, each entry takes part in about log2(len(parts))
    merges. `parts` is emptied as it goes, so each matrix is freed once merged (the
    memory peak is the parts plus one level of sums, not every level).

    Parameters
    ----------
    parts : list of csr_matrix
        At least one, all of one shape; the list is left empty.

    Returns
    -------
    csr_matrix
        Canonical, exact zeros (entries that cancelled) dropped.
    """
    while len(parts) > 1:
        merged = []
        while parts:
            left = parts.pop(0)
            merged.append(left + parts.pop(0) if parts else left)
            del left
        parts.extend(merged)
        del merged
    out = parts.pop().tocsr()
    out.sum_duplicates()
    out.eliminate_zeros()              # as an addition drops the entries that cancel
    return out


def symmetric_from_upper(upper: sparse.csr_matrix, diagonal: np.ndarray
                         ) -> sparse.csr_matrix:
    """``U + U^T + diag(diagonal)`` for a canonical strictly upper triangular `upper`.

    Row i of the result is row i of ``U^T`` (columns below i), the diagonal, then row i
    of ``U`` (columns above i): each already sorted, so they are only placed side by
    side. The diagonal is stored even where zero (an SPD matrix has none).

    Parameters
    ----------
    upper : (n, n) csr_matrix
        Canonical, entries only above the diagonal.
    diagonal : (n,) ndarray

    Returns
    -------
    csr_matrix
        Canonical and exactly symmetric (mirrored, not recomputed).
    """
    n = upper.shape[0]
    lower = upper.tocsc()              # CSC of U = CSR of U^T, sorted (a counting sort)
    u_ptr, l_ptr = upper.indptr.astype(np.int64), lower.indptr.astype(np.int64)
    u_len, l_len = np.diff(u_ptr), np.diff(l_ptr)
    nnz = int(u_ptr[-1] + l_ptr[-1]) + n
    dtype = _index(max(nnz, n) + 1)
    indptr = (u_ptr + l_ptr + np.arange(n + 1)).astype(dtype)
    indices = np.empty(nnz, dtype=dtype)
    data = np.empty(nnz, dtype=np.result_type(upper.dtype, diagonal.dtype))
    # which of the three lists each position takes, row after row (lower, diagonal,
    # upper): boolean masks place them in order, sequentially, with no index arrays
    lengths = np.stack([l_len, np.ones(n, dtype=np.int64), u_len], axis=1).ravel()
    kind = np.repeat(np.tile(np.arange(3, dtype=np.int8), n), lengths)
    for code, (where_indices, where_data) in enumerate(
            ((lower.indices, lower.data), (np.arange(n, dtype=dtype), diagonal),
             (upper.indices, upper.data))):
        mask = kind == code
        indices[mask], data[mask] = where_indices, where_data
    del kind, mask, lower
    out = sparse.csr_matrix((data, indices, indptr), shape=(n, n))
    out.has_sorted_indices = True
    out.has_canonical_format = True
    return out
