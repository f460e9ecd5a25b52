"""Eigenvalues and the least eigenvector of many symmetric 3 x 3 matrices, in closed form.

Surface normals are the least eigenvector of each point's neighbourhood covariance, and a
log asks for 20,000-70,000 of them a frame. LAPACK's ``eigh`` solves each 3 x 3 matrix
with a general iterative method, 1-3 microseconds apiece; the characteristic cubic has a
trigonometric solution (Smith, "Eigenvalues of a symmetric 3 x 3 matrix", CACM 1961) and
the least eigenvector is a cross product of two rows of ``A - l_0 I`` (each column of its
adjugate lies along it), a few vectorised passes: a sixth to a seventh of ``eigh``'s time
on real sweeps, with normals within 1e-7 of its. Where the least eigenvalue is nearly
repeated (a line of points, a single point repeated) the cross products lose their
digits; those matrices go to ``eigh``. So do batches of fewer than ``_FEW`` matrices
(most of a log's batches hold a handful), for which one LAPACK call costs less than the
closed form's forty array operations.
"""

import numpy as np

__all__ = ["least_eigenvectors"]

# The product of the least eigenvalue's gaps to the other two, as a share of the largest
# eigenvalue squared, below which the closed form's eigenvector is left to LAPACK: the
# cross products' relative error is about machine epsilon over this share.
_MIN_GAPS = 1e-6
# Batches smaller than this go to LAPACK whole (on scene-0004's batches: 32 took 0.07 s
# against 0.24 s for LAPACK alone and 0.12 s for the closed form alone).
_FEW = 32


def least_eigenvectors(matrices):
    """Eigenvalues (ascending) and a unit eigenvector of the least, of each matrix.

    Parameters
    ----------
    matrices : ndarray of shape (n, 3, 3)
        Symmetric matrices (covariances: positive semi-definite, though any symmetric
        matrix is solved).

    Returns
    -------
    values : ndarray of shape (n, 3)
        The eigenvalues, ascending, as ``numpy.linalg.eigh`` gives them (to rounding).
    vectors : ndarray of shape (n, 3)
        A unit eigenvector of each least eigenvalue, of either sign.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.symmetric3 import least_eigenvectors
    >>> values, vectors = least_eigenvectors(np.diag([4.0, 1.0, 9.0])[None])
    >>> values.round(12).tolist(), np.abs(vectors).round(12).tolist()
    ([[1.0, 4.0, 9.0]], [[0.0, 1.0, 0.0]])
    """
    a = np.asarray(matrices, dtype=float)
    if len(a) < _FEW:
        values, vectors = np.linalg.eigh(a)
        return values, vectors[:, :, 0]
    a00, a11, a22 = a[:, 0, 0], a[:, 1, 1], a[:, 2, 2]
    a01, a02, a12 = a[:, 0, 1], a[:, 0, 2], a[:, 1, 2]
    # A = q I + p B with B's trace 0 and norm sqrt(6): its eigenvalues are 2 cos of the
    # angles (acos(det(B) / 2) + 2 pi k) / 3.
    q = (a00 + a11 + a22) / 3
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    off = a01 * a01 + a02 * a02 + a12 * a12
    p = np.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2 * off) / 6)
    determinant = (
        b00 * (b11 * b22 - a12 * a12)
        - a01 * (a01 * b22 - a12 * a02)
        + a02 * (a01 * a12 - b11 * a02)
    )
    cosine = np.clip(determinant / (2 * np.where(p > 0, p, 1.0) ** 3), -1.0, 1.0)
    angle = np.arccos(cosine) / 3
    top = q + 2 * p * np.cos(angle)
    least = q + 2 * p * np.cos(angle + 2 * np.pi / 3)
    middle = 3 * q - least - top
    values = np.stack([least, middle, top], axis=1)
    # The rows of A - l_0 I and their three cross products, component by component
    # (numpy's cross costs more than the arithmetic on these short arrays).
    d0, d1, d2 = a00 - least, a11 - least, a22 - least
    crosses = np.empty((3, len(a), 3))
    crosses[0, :, 0] = a01 * a12 - a02 * d1  # row 0 x row 1
    crosses[0, :, 1] = a02 * a01 - d0 * a12
    crosses[0, :, 2] = d0 * d1 - a01 * a01
    crosses[1, :, 0] = a01 * d2 - a02 * a12  # row 0 x row 2
    crosses[1, :, 1] = a02 * a02 - d0 * d2
    crosses[1, :, 2] = d0 * a12 - a01 * a02
    crosses[2, :, 0] = d1 * d2 - a12 * a12  # row 1 x row 2
    crosses[2, :, 1] = a12 * a02 - a01 * d2
    crosses[2, :, 2] = a01 * a12 - d1 * a02
    lengths = np.einsum("cni,cni->cn", crosses, crosses)
    best = lengths.argmax(axis=0)
    picked = np.arange(len(a))
    vectors = crosses[best, picked]
    length = np.sqrt(lengths[best, picked])
    largest = np.maximum(np.abs(values).max(axis=1), np.finfo(float).tiny)
    solved = ((middle - least) * (top - least) > _MIN_GAPS * largest * largest) & (length > 0)
    vectors /= np.where(solved, length, 1.0)[:, None]
    hard = np.flatnonzero(~solved)
    if len(hard):
        hard_values, hard_vectors = np.linalg.eigh(a[hard])
        values[hard] = hard_values
        vectors[hard] = hard_vectors[:, :, 0]
    return values, vectors
