"""Distances between two sets of feature vectors: KID and FID.

Both take features [N, D] (any float dtype; computed in float64) from a
:class:`mesh2tex.metrics.features.FeatureExtractor`; what the numbers mean depends on those features
(see that module for the names they are reported under).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import torch

from mesh2tex.checks import check_array_shape, check_shape


def kid(
    features_a: torch.Tensor, features_b: torch.Tensor, num_subsets: int = 100, subset_size: int = 1000, seed: int = 0
) -> tuple[float, float]:
    """Kernel Inception Distance: the unbiased squared MMD with the cubic polynomial kernel
    k(x, y) = (x . y / D + 1)^3, averaged over ``num_subsets`` random subsets of
    min(subset_size, N_a, N_b) vectors from each set.

    Returns (mean, standard deviation over subsets). Unbiased, so it can be slightly negative for
    two samples of one distribution. Published tables often show it times 100 (Mesh2Tex) or 1000.
    features_a [N, D] and features_b [M, D] float.
    """
    sizes = check_shape(features_a, "kid: features_a", ("N", "D"), dtype="float")
    check_shape(features_b, "kid: features_b", ("M", "D"), sizes=sizes, dtype="float")
    a = features_a.double().cpu()
    b = features_b.double().cpu()
    dim = a.shape[1]
    size = min(subset_size, a.shape[0], b.shape[0])
    if size < 2:
        raise ValueError("KID needs at least 2 feature vectors in each set")
    generator = torch.Generator().manual_seed(seed)
    values = []
    for _ in range(num_subsets):
        x = a[torch.randperm(a.shape[0], generator=generator)[:size]]
        y = b[torch.randperm(b.shape[0], generator=generator)[:size]]
        k_xx = (x @ x.T / dim + 1) ** 3
        k_yy = (y @ y.T / dim + 1) ** 3
        k_xy = (x @ y.T / dim + 1) ** 3
        off_diagonal = size * (size - 1)
        mmd = (
            (k_xx.sum() - k_xx.diagonal().sum()) / off_diagonal
            + (k_yy.sum() - k_yy.diagonal().sum()) / off_diagonal
            - 2 * k_xy.mean()
        )
        values.append(float(mmd))
    return float(np.mean(values)), float(np.std(values))


def fid(features_a: torch.Tensor, features_b: torch.Tensor) -> float:
    """Frechet distance between Gaussians fitted to the two sets:
    |mu_a - mu_b|^2 + tr(S_a + S_b - 2 (S_a S_b)^(1/2)).

    Computed exactly without a general matrix square root (see :func:`trace_sqrt_product`). With
    few vectors the estimate is biased upwards: FID needs thousands of images to be comparable
    across papers; with tens of images, compare values only at equal set sizes. features_a [N, D] and
    features_b [M, D] float.
    """
    sizes = check_shape(features_a, "fid: features_a", ("N", "D"), dtype="float")
    check_shape(features_b, "fid: features_b", ("M", "D"), sizes=sizes, dtype="float")
    a = features_a.double().cpu().numpy()
    b = features_b.double().cpu().numpy()
    if a.shape[0] < 2 or b.shape[0] < 2:
        raise ValueError("FID needs at least 2 feature vectors in each set")
    mu_a, mu_b = a.mean(0), b.mean(0)
    centred_a, centred_b = a - mu_a, b - mu_b
    trace_a = (centred_a**2).sum() / (a.shape[0] - 1)
    trace_b = (centred_b**2).sum() / (b.shape[0] - 1)
    return float(((mu_a - mu_b) ** 2).sum() + trace_a + trace_b - 2 * trace_sqrt_product(centred_a, centred_b))


def trace_sqrt_product(centred_a: np.ndarray, centred_b: np.ndarray) -> float:
    """tr((S_a S_b)^(1/2)) for the covariances S = X^T X / (n - 1) of centred rows X [n, D], exactly.

    With S_a = A^T A and S_b = B^T B, the non-zero eigenvalues of S_a S_b are those of
    (A B^T)(A B^T)^T, so the trace is the sum of the singular values of A B^T [n_a, n_b]; when the
    sets are larger than D, the same sum comes from the D x D symmetric form S_a^(1/2) S_b S_a^(1/2).
    Both avoid a general matrix square root (slow, and inaccurate for singular covariances).
    centred_a [n_a, D] and centred_b [n_b, D] NumPy arrays.
    """
    sizes = check_array_shape(centred_a, "trace_sqrt_product: centred_a", ("n_a", "D"))
    check_array_shape(centred_b, "trace_sqrt_product: centred_b", ("n_b", "D"), sizes=sizes)
    n_a, n_b = centred_a.shape[0], centred_b.shape[0]
    dim = centred_a.shape[1]
    if min(n_a, n_b) <= dim:
        cross = centred_a @ centred_b.T / np.sqrt((n_a - 1) * (n_b - 1))
        return float(scipy.linalg.svdvals(cross).sum())
    sigma_a = centred_a.T @ centred_a / (n_a - 1)
    sigma_b = centred_b.T @ centred_b / (n_b - 1)
    values, vectors = np.linalg.eigh(sigma_a)
    root_a = (vectors * np.sqrt(values.clip(min=0))) @ vectors.T
    inner = np.linalg.eigvalsh(root_a @ sigma_b @ root_a)
    return float(np.sqrt(inner.clip(min=0)).sum())
