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

__all__ = ["PairwiseSum", "matvec_into", "sum_pairwise", "symmetric_from_upper"]


def _index(n: int) -> type:
    return np.int32 if n < 2 ** 31 - 1 else np.int64


def matvec_into(matrix: sparse.csr_matrix | sparse.csc_matrix, x: np.ndarray,
                out: np.ndarray) -> np.ndarray:
    """``matrix @ x`` for a vector, written into `out` (returned) instead of a new vector.

    scipy's own CSR/CSC kernel adds into the zeroed `out`, which is what ``@`` does into
    a vector it makes: the same sums in the same order, bit for bit. The one place the
    solve reaches into scipy's private kernels; `x`, `out` and the matrix's data share
    one dtype.
    """
    from scipy.sparse import _sparsetools

    kernel = _sparsetools.csr_matvec if matrix.format == "csr" else _sparsetools.csc_matvec
    out.fill(0.0)
    kernel(matrix.shape[0], matrix.shape[1], matrix.indptr, matrix.indices, matrix.data,
           x, out)
    return out


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


class PairwiseSum:
    """:func:`sum_pairwise` of matrices given one at a time, held in row blocks.

    The same sum, entry for entry and bit for bit: the tree of :func:`sum_pairwise`
    (pairs from the left, level by level) is the binary counter's, each matrix merged as
    soon as one of its size waits, and the last ones folded from the right. Rows are
    added independently, so each matrix is kept as `blocks` CSR row blocks and a merge
    frees its operands' blocks as it goes: the peak is what is held (the counter's few
    partial sums) and one block, not every batch at once and then two levels of sums
    (P2 at 128^3: 29 batches, each with a full-length row pointer). :meth:`result`
    copies the blocks into one matrix the same way.

    Parameters
    ----------
    shape : (int, int)
    blocks : int
        Row blocks per matrix.
    """

    def __init__(self, shape: tuple[int, int], blocks: int = 16):
        self.shape = (int(shape[0]), int(shape[1]))
        edges = np.linspace(0, self.shape[0], max(1, min(blocks, self.shape[0])) + 1)
        self._rows = np.unique(edges.astype(np.int64))
        self._stack: list[tuple[int, list]] = []        # (matrices summed, row blocks)

    def add(self, matrix: sparse.csr_matrix) -> None:
        """Take `matrix`, its rows copied into blocks; :meth:`merge` sums it in (called
        after the caller has dropped `matrix` and what it was made from)."""
        rows = self._rows
        self._stack.append((1, [matrix[a:b] for a, b in zip(rows[:-1], rows[1:])]))

    def merge(self) -> None:
        """The sums that are due: while the two last partial sums are of one size."""
        while len(self._stack) > 1 and self._stack[-1][0] == self._stack[-2][0]:
            self._merge()

    def _merge(self) -> None:
        right_count, right = self._stack.pop()
        left_count, left = self._stack.pop()
        out = []
        for k in range(len(left)):
            out.append(left[k] + right[k])
            left[k] = right[k] = None                    # freed as the sum goes
        self._stack.append((left_count + right_count, out))

    def result(self) -> sparse.csr_matrix:
        """The sum (canonical, exact zeros dropped, as :func:`sum_pairwise`); empties it."""
        if not self._stack:
            return sparse.csr_matrix(self.shape)
        self.merge()
        while len(self._stack) > 1:
            self._merge()
        blocks = self._stack.pop()[1]
        for block in blocks:
            block.sum_duplicates()
            block.eliminate_zeros()
        nnz = sum(int(b.nnz) for b in blocks)
        dtype = _index(max(nnz, *self.shape) + 1)
        data = np.empty(nnz, dtype=np.result_type(*[b.dtype for b in blocks]))
        indices: np.ndarray = np.empty(nnz, dtype=dtype)
        indptr: np.ndarray = np.empty(self.shape[0] + 1, dtype=dtype)
        indptr[0] = at = 0
        for k, start in enumerate(self._rows[:-1]):
            block, blocks[k] = blocks[k], None           # each block freed once copied
            end = at + int(block.nnz)
            data[at:end], indices[at:end] = block.data, block.indices
            indptr[start + 1:start + 1 + block.shape[0]] = block.indptr[1:] + at
            at = end
            del block
        out = sparse.csr_matrix((data, indices, indptr), shape=self.shape)
        out.has_sorted_indices = True
        out.has_canonical_format = True
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
