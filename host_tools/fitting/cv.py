"""Cross-validation shared by the fitter (host_tools.fitting.fit: ``_CV`` / ``select_terms``, terms
'auto') and the closed loop (host_tools.fitting.diagnose: the candidate scan and the whole-model steps):
ONE fold definition and ONE held-out error algebra.

Folds
-----
* several runs: one fold per run (leave one run out);
* one run: ``n_blocks`` contiguous, equal-length time blocks (:func:`block_ids`: sample i of n is
  in block ``floor(i * n_blocks / n)``), dealt round-robin into ``n_folds`` folds (block b ->
  fold ``b % n_folds``, :func:`fold_ids`).  Each fold then holds contiguous stretches spread over
  the whole run, so no fold extrapolates the polynomial in the proxy; never random samples.
  With ``n_folds == n_blocks`` every block is its own fold (what ``hdrg fit --terms auto`` does).

Held-out error
--------------
For a least-squares system written in sums over the held-out samples, S = sum y^2 (or sum w y^2),
B = X^T y, A = X^T X, the held-out sum of squared errors of coefficients b is
``S - 2 b.B + b.A b`` (:func:`heldout_sse`; b a vector, or one column per target).
:func:`cv_se` is the standard error of the CV mean squared error from the spread of the per-fold
errors (the one-standard-error rule of ``select_terms``).
"""
from __future__ import annotations

import math

import numpy as np


def block_ids(n: int, n_blocks: int) -> np.ndarray:
    """Block id 0..n_blocks-1 of each of ``n`` samples: contiguous, equal-length time blocks."""
    if n_blocks < 1:
        raise ValueError(f"cv_blocks must be >= 1, got {n_blocks}")
    return (np.arange(n, dtype=np.int64) * n_blocks) // max(n, 1)


def fold_ids(n: int, n_blocks: int, n_folds: int | None = None) -> np.ndarray:
    """Fold id of each of ``n`` samples of one run: its block (:func:`block_ids`) mod ``n_folds``
    (None: ``n_blocks``, every block its own fold)."""
    if n_folds is None:
        n_folds = n_blocks
    if n_folds < 2 or n_blocks < n_folds:
        raise ValueError(f"a single training run needs cv_folds >= 2 and cv_blocks >= cv_folds "
                         f"(got {n_blocks} blocks, {n_folds} folds)")
    return block_ids(n, n_blocks) % n_folds


def heldout_sse(b, S, B, A):
    """Held-out sum of squared errors ``S - 2 b.B + b.A b`` of coefficients ``b`` on a held-out
    system (S = sum y^2, B = X^T y, A = X^T X over the held-out samples).  ``b`` of shape (p,):
    a float; (p, k) with B (p, k) and S (k,): one value per target column."""
    b = np.asarray(b)
    if b.ndim == 1:
        return S - 2.0 * float(b @ B) + float(b @ A @ b)
    return S - 2.0 * np.einsum("ij,ij->j", b, B) + np.einsum("ij,ij->j", b, A @ b)


def cv_se(e, sw) -> float:
    """Standard error of the CV mean squared error sum(e) / sum(sw) from the spread of the
    per-fold MSEs e_f / sw_f (folds weighted by their total weight sw_f)."""
    mse = e.sum() / sw.sum()
    g = len(e)
    return math.sqrt(g / (g - 1) * float(np.sum(sw ** 2 * (e / np.where(sw > 0, sw, 1) - mse) ** 2))) / sw.sum()
