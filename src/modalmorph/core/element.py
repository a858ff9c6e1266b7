"""Sclaroff's isoparametric Gaussian element: closed forms of its integrals (1)-(5).

Every integral is over all of R^d and has a closed form (method.md §1). With
``r = X_j - X_i``, ``e_ij = exp(-|r|^2 / (4 sigma^2))`` and ``V = (pi sigma^2)^(d/2)``:

- ``G_ij = g_j(X_i) = e_ij^2``                    (2), the interpolation matrix
- ``Gamma_ij = V e_ij``                           (integral of g_i g_j)
- ``D^ab_ij = V e_ij / sigma^4 (delta_ab sigma^2 / 2 - r_a r_b / 4)``  (of dg_i/dx_a dg_j/dx_b)

The physical matrices use ``A = G^-1``: ``M = rho (I_d kron A Gamma A)`` and
``K_ab = A [(lambda + mu) D^ab + mu delta_ab sum_c D^cc] A``
(:class:`modalmorph.core.model.FEModel` assembles them). This module holds the entries,
the choice and the checks of sigma, and the radius beyond which a truncated model drops
an interaction: every entry decays like
``exp(-|r|^2 / (4 sigma^2))`` and sigma is a multiple of the node spacing, so each node
interacts with a bounded number of others.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

from ..errors import ModelError, OptionError
from .shape import as_shape

__all__ = ["DEFAULT_SIGMA", "AUTO_CONDITION", "MAX_CONDITION", "MIN_SIGMA", "MAX_SIGMA",
           "DEFAULT_CUTOFF", "AUTO_DENSE_MAX_DOF", "auto_sigma", "check_sigma",
           "cutoff_radius", "gaussian", "gram_entries", "squared_norms", "stiffness_entries",
           "stiffness_matrix",
           "stiffness_components", "stiffness_component_pairs", "self_entries",
           "gaussian_from_overlap", "condition_bound",
           "auto_sigma_condition", "singular_gram"]

# sigma in units of the mean nearest-neighbour spacing; chosen by measurement, see README.
DEFAULT_SIGMA = 1.0
# sigma=None: the widest width up to the nominal one with cond(Gamma) <= this (method.md §1).
AUTO_CONDITION = 1e10
# Beyond this condition number of Gamma the mass-normalisation loses more than ~4 of its
# 16 digits (Phi^T M Phi = I is then only good to ~1e-4): refuse instead of returning noise.
MAX_CONDITION = 1e12
# Below this sigma neighbouring nodes overlap by less than exp(-1 / (4 * 0.05^2)) = e^-100:
# they do not interact and the model degenerates (all-NaN modes at 1e-100).
MIN_SIGMA = 0.05
# Above this sigma the Gram matrix of any shape of more than a few nodes is numerically
# singular (condition numbers 1e9-1e17 already at sigma 3, measured as above).
MAX_SIGMA = 10.0
# A truncated model drops every interaction smaller than this fraction of the diagonal.
DEFAULT_CUTOFF = 1e-10
# Largest eigenproblem solved densely unasked, in d * m: all modes in ~1 s (method.md §7).
AUTO_DENSE_MAX_DOF = 3000
# auto_sigma stops within this many decades below AUTO_CONDITION, or after _AUTO_STEPS.
_AUTO_SLACK, _AUTO_STEPS = 0.5, 8
# A dense K_g is evaluated a few rows at a time, each (rows, m) temporary (its scale and
# diagonal term) at most this size: below glibc's default 128 KiB mmap threshold, they
# reuse freed heap where whole (m, m) ones took fresh pages (issue 22: a 250-node
# morph's K_g took 854 minor page faults, 366 of them its temporaries).
_CHUNK_BYTES = 120 * 1024


def _volume(sigma: float, d: int) -> float:
    """``V = (pi sigma^2)^(d/2)``, the integral of ``g_i g_i``."""
    return (np.pi * sigma**2) ** (d / 2)


def _squared_norm(r: np.ndarray) -> np.ndarray:
    return np.einsum("...a,...a->...", r, r)


def gaussian(r2: np.ndarray, sigma: float) -> np.ndarray:
    """The shape function ``g_j(x) = exp(-|x - X_j|^2 / (2 sigma^2))`` (2) at squared
    distances ``r2``."""
    return np.exp(-r2 / (2 * sigma**2))


def gaussian_from_overlap(gamma: np.ndarray, sigma: float, d: int) -> np.ndarray:
    """``G_ij = (Gamma_ij / V)^2``: the entries of ``G`` from those of ``Gamma`` at the same
    offsets, without the offsets (``e_ij^2 = exp(-|r|^2 / (2 sigma^2))``)."""
    return np.square(gamma / _volume(sigma, d))


def squared_norms(r: np.ndarray) -> np.ndarray:
    """``|r|^2`` of offsets ``r`` (..., d), shape ``r.shape[:-1]`` (the ``r2`` that
    :func:`gram_entries` and :func:`stiffness_entries` accept to share it)."""
    return _squared_norm(r)


def gram_entries(r: np.ndarray, sigma: float, r2: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Entries of ``G`` (1)-(2) and ``Gamma`` for node offsets ``r`` (..., d); ``r2``:
    their :func:`squared_norms` when already computed.

    Returns ``(g, gamma)``, each of shape ``r.shape[:-1]``.
    """
    r2 = _squared_norm(r) if r2 is None else r2
    return gaussian(r2, sigma), _overlap(r2, sigma, r.shape[-1])


def _overlap(r2: np.ndarray, sigma: float, d: int) -> np.ndarray:
    """``Gamma_ij = V exp(-|r|^2 / (4 sigma^2))`` at squared distances ``r2``."""
    return _volume(sigma, d) * np.exp(-r2 / (4 * sigma**2))


def stiffness_component_pairs(d: int) -> list[tuple[int, int]]:
    """The distinct ``(a, b)`` of the symmetric blocks ``K_g^ab``: the ``d`` diagonal
    components, then ``a < b``, the order of :func:`stiffness_components`."""
    return [(a, a) for a in range(d)] + [(a, b) for a in range(d) for b in range(a + 1, d)]


def stiffness_components(r: np.ndarray, sigma: float, lam: float, mu: float,
                         ) -> tuple[list[np.ndarray], np.ndarray]:
    """The distinct entries of the stiffness blocks in the Gaussian basis for offsets
    ``r`` (..., d), and ``Gamma`` there (one exponential for both).

    Returns ``([K^ab for (a, b) in stiffness_component_pairs(d)], gamma)``, each of shape
    ``r.shape[:-1]``; ``K^ab = K^ba`` (see :func:`stiffness_entries`).
    """
    return _stiffness(r, sigma, lam, mu, stiffness_component_pairs(r.shape[-1]))


def stiffness_entries(r: np.ndarray, sigma: float, lam: float, mu: float, *,
                      r2: np.ndarray | None = None, gamma: np.ndarray | None = None
                      ) -> np.ndarray:
    """Blocks of the stiffness in the Gaussian basis, ``K_g[..., a, b]``, for offsets ``r``.

    ``K_g^ab = (lambda + mu) D^ab + mu delta_ab sum_c D^cc``
    ``= s (-(lambda + mu) / 4 r_a r_b + delta_ab t)`` with ``s = Gamma / sigma^4`` and
    ``t = (lambda + mu) sigma^2 / 2 + mu (d sigma^2 / 2 - |r|^2 / 4)``, shape
    ``r.shape + (d,)``: a view of a (d, d) + ``r.shape[:-1]`` array, one contiguous block
    per component (faster to fill, and to lay out component-major (7), than d x d blocks).
    ``r2`` and ``gamma``: :func:`squared_norms` of ``r`` and ``Gamma`` there
    (:func:`gram_entries`) when already computed (the same numbers, not computed twice).
    """
    d = r.shape[-1]
    pairs = [(a, b) for a in range(d) for b in range(d)]
    out = np.empty((d, d) + r.shape[:-1])
    blocks = _stiffness(r, sigma, lam, mu, pairs, r2, gamma)[0]
    for (a, b), v in zip(pairs, blocks, strict=True):
        out[a, b] = v
    return np.moveaxis(out, (0, 1), (-2, -1))


def stiffness_matrix(r: np.ndarray, sigma: float, lam: float, mu: float, *,
                     r2: np.ndarray | None = None, gamma: np.ndarray | None = None,
                     order: str = "C") -> np.ndarray:
    """The dense stiffness in the Gaussian basis, ``K_g`` (dm, dm), component-major (7),
    for the offsets ``r`` (m, m, d) of all node pairs: the entries of
    :func:`stiffness_entries`, each block evaluated in place where it lies, a few rows at
    a time (temporaries of at most ``_CHUNK_BYTES``; no (m, m, d, d) array and no
    transposed copy of it; bitwise the same numbers). ``order="F"``: the same numbers
    laid out in Fortran order (LAPACK's), written as the C-ordered transpose from the
    transposed offsets (``r_ji`` is ``r_ij`` read the other way round; ``r2`` and
    ``gamma`` are exactly symmetric)."""
    if order not in ("C", "F"):
        raise ValueError(f"order must be 'C' or 'F', got {order!r}")
    m, d = r.shape[0], r.shape[-1]
    pairs = [(a, b) for a in range(d) for b in range(d)]
    if order == "F":  # K^ab_ij to [b, j, a, i] of the C view of a Fortran (dm, dm) array
        full = np.empty((d * m, d * m), order="F")
        out = full.T.reshape(d, m, d, m).transpose(2, 1, 0, 3)
        r = r.transpose(1, 0, 2)
        r2, gamma = (None if r2 is None else r2.T), (None if gamma is None else gamma.T)
    else:
        full = out = np.empty((d, m, d, m))
    step = max(1, _CHUNK_BYTES // (8 * m))
    for i in range(0, m, step):
        at = slice(i, i + step)
        r2_at = _squared_norm(r[at]) if r2 is None else r2[at]
        gamma_at = _overlap(r2_at, sigma, d) if gamma is None else gamma[at]
        _blocks(r[at], sigma, lam, mu, pairs, r2_at, gamma_at, out[:, at])
    return full.reshape(d * m, d * m)


def self_entries(sigma: float, d: int, lam: float, mu: float) -> tuple[float, float]:
    """``(K_g^aa_ii, Gamma_ii)``: the stiffness and the mass (without rho) of one node and
    one component in the Gaussian basis, the diagonal entries at offset 0,
    ``V / sigma^2 ((lambda + mu) / 2 + mu d / 2)`` and ``V``: the reference scales of a
    model's loads and time step."""
    components, gamma = stiffness_components(np.zeros(d), sigma, lam, mu)
    return float(components[0]), float(gamma)


def _stiffness(r: np.ndarray, sigma: float, lam: float, mu: float,
               pairs: list[tuple[int, int]], r2: np.ndarray | None = None,
               gamma: np.ndarray | None = None) -> tuple[list[np.ndarray], np.ndarray]:
    """``[K_g^ab for (a, b) in pairs]`` and ``Gamma`` for offsets ``r`` (..., d).

    Every ``(a, b)`` is evaluated as written, ``(-(lambda + mu) / 4 r_a) r_b``: ``K^ab``
    and ``K^ba`` may differ in the last bit, as they always have (the multilevel solver's
    iterations would carry a change of that bit to 1e-9 in its frequencies).
    """
    d = r.shape[-1]
    r2 = _squared_norm(r) if r2 is None else r2
    gamma = _overlap(r2, sigma, d) if gamma is None else gamma
    return _blocks(r, sigma, lam, mu, pairs, r2, gamma, None), gamma


def _blocks(r, sigma, lam, mu, pairs, r2, gamma, out) -> list[np.ndarray]:
    """:func:`_stiffness`'s blocks for offsets ``r`` with their ``r2`` and ``gamma``
    (also written to ``out[a, :, b]`` for ``out`` (d, rows, d, m))."""
    d = r.shape[-1]
    scale = gamma / sigma**4
    diag = (lam + mu) * sigma**2 / 2 + mu * (d * sigma**2 / 2 - r2 / 4)
    # into ``out`` (a dense K_g, a chunk of rows): each component read contiguous once,
    # each block made contiguous and copied in place: 123 -> 74 us at 70 nodes in Fortran
    # order (strided reads and writes before), the same numbers; else views (no copies)
    comp = [np.ascontiguousarray(r[..., a]) if out is not None else r[..., a]
            for a in range(d)]
    blocks = []
    for a, b in pairs:
        v = np.multiply(-(lam + mu) / 4, comp[a])
        v *= comp[b]
        if a == b:
            v += diag
        v *= scale
        if out is not None:
            out[a, :, b] = v
        blocks.append(v)
    return blocks


def cutoff_radius(sigma: float, cutoff: float = DEFAULT_CUTOFF) -> float:
    """Distance beyond which the sparse model drops the interaction of two nodes.

    The radius ``2 sigma sqrt(x)`` where ``2 x exp(-x) = cutoff`` (``x >= 1``): beyond it,
    every entry of ``G`` (decaying like ``exp(-2x)``), ``Gamma`` (``exp(-x)``) and ``K_g``
    (at most ``2 x exp(-x)`` of its diagonal) is below ``cutoff`` times the diagonal.
    ``cutoff = 1e-10`` gives ``x = 26.3``, a radius of 10.3 sigma.
    """
    if not 0 < cutoff < 1:
        raise OptionError(f"cutoff must be in (0, 1), got {cutoff}")
    target = np.log(1 / cutoff)
    x = max(target, 1.0)
    for _ in range(100):  # fixed point of x = log(1/cutoff) + log(2x), a contraction
        x_new = target + np.log(2 * x)
        if abs(x_new - x) < 1e-12 * x:
            break
        x = x_new
    return float(2 * sigma * np.sqrt(x_new))


def _log_condition(r2: np.ndarray, sigma: float) -> float:
    """log10 of the condition number of ``Gamma`` for squared distances ``r2`` (m, m) and
    an absolute sigma (the factor V of :func:`gram_entries` cancels); capped at 17, where
    the smallest eigenvalue is lost in double-precision round-off."""
    ev = np.linalg.eigvalsh(_overlap(r2, sigma, d=0))  # V = 1: it cancels in the ratio
    return float(min(np.log10(ev[-1] / ev[0]), 17.0)) if ev[0] > 0 else 17.0


def condition_bound(gamma: np.ndarray, l_inv: np.ndarray) -> float:
    """An upper bound of the condition number of a Gram matrix ``Gamma`` (positive
    entries) from the inverse ``l_inv`` of its lower Cholesky factor: its largest
    eigenvalue is at most its largest row sum (Gershgorin), its smallest at least
    ``1 / trace(Gamma^-1) = 1 / |L^-1|_F^2``. Within 1-40x of the condition number on
    hearts and glyphs of 70-400 nodes at 1 and 2 spacings (cheaper than the eigenvalues:
    a factor and a triangular inverse)."""
    with np.errstate(over="ignore"):  # inf: no bound
        return float(gamma.sum(axis=1).max() * np.einsum("ij,ij->", l_inv, l_inv))


def _condition_below(r2: np.ndarray, sigma: float, log_limit: float) -> bool:
    """Whether :func:`condition_bound` shows the condition number of ``Gamma`` at
    ``sigma`` to be at most ``10^log_limit`` (False when it cannot)."""
    gamma = _overlap(r2, sigma, d=0)
    L, info = lapack.dpotrf(gamma, lower=1, clean=1)
    if info == 0:
        L, info = lapack.dtrtri(L, lower=1, overwrite_c=1)
    return info == 0 and condition_bound(gamma, L) <= 10.0**log_limit


def auto_sigma(shape, nominal: float = DEFAULT_SIGMA) -> float:
    """The Gaussian width (x mean node spacing) used when ``sigma=None``.

    ``nominal`` if the Gram matrix ``Gamma`` is well conditioned there (condition number at
    most ``AUTO_CONDITION``), else the largest width below it that is, within a factor
    10^0.5 of the limit: log10 of the condition number is close to linear in sigma^2
    (measured on circles, glyphs and hands), so a few steps of regula falsi in sigma^2
    find it. Objects too large for a dense Gram matrix (more than ``AUTO_DENSE_MAX_DOF``
    degrees of freedom) get ``nominal``: their solvers check the conditioning themselves.
    """
    return auto_sigma_condition(shape, nominal)[0]


def auto_sigma_condition(shape, nominal: float = DEFAULT_SIGMA) -> tuple[float, float | None]:
    """:func:`auto_sigma` and log10 of Gamma's condition number there (None when not
    computed: objects too large for a dense Gram matrix, or ``nominal`` shown well
    conditioned by :func:`condition_bound`)."""
    shape = as_shape(shape)
    if shape.dim * shape.m > AUTO_DENSE_MAX_DOF:
        return float(nominal), None
    x = shape.normalized
    r2 = np.maximum(np.sum(x**2, 1)[:, None] + np.sum(x**2, 1)[None, :] - 2 * x @ x.T, 0.0)
    h, target = shape.spacing, np.log10(AUTO_CONDITION)
    if _condition_below(r2, nominal * h, target):  # no eigenvalues needed
        return float(nominal), None
    hi, c_hi = float(nominal), _log_condition(r2, nominal * h)
    if c_hi <= target:
        return hi, c_hi
    lo, c_lo = hi, c_hi
    while c_lo > target and lo > MIN_SIGMA:  # halve until well conditioned
        hi, c_hi = lo, c_lo
        lo = max(lo / 2, MIN_SIGMA)
        c_lo = _log_condition(r2, lo * h)
    for _ in range(_AUTO_STEPS):
        if target - c_lo <= _AUTO_SLACK:
            break
        q = lo**2 + (target - _AUTO_SLACK / 2 - c_lo) * (hi**2 - lo**2) / (c_hi - c_lo)
        s, c = float(np.sqrt(q)), _log_condition(r2, np.sqrt(q) * h)
        if c <= target:
            lo, c_lo = s, c
        else:
            hi, c_hi = s, c
    return lo, c_lo


def check_sigma(sigma) -> None:
    """Refuse a sigma that is not None or a number in [MIN_SIGMA, MAX_SIGMA]."""
    if sigma is None:
        return
    if not isinstance(sigma, int | float | np.integer | np.floating) or not (
            MIN_SIGMA <= sigma <= MAX_SIGMA):
        raise OptionError(f"sigma must be None (chosen per shape) or a number between "
                         f"{MIN_SIGMA:g} and {MAX_SIGMA:g} (x mean node spacing), got {sigma!r}")


def singular_gram(shape, sigma_rel: float, cond: float | None = None,
                  detail: str = "") -> ModelError:
    """The error for a sigma so large that the Gram matrix of ``shape`` is numerically
    singular (condition number ``cond`` when measured), naming the width that works."""
    shape = as_shape(shape)
    what = f" (condition number {cond:.1e})" if cond is not None else ""
    gap, i, j = _closest_nodes(shape)
    if gap < MIN_SIGMA:  # closer than the narrowest width: no sigma separates them
        return ModelError(
            f"nodes {i} and {j} of this {shape.m}-node shape are {gap:.2g} x the mean node "
            f"spacing apart, closer than the narrowest Gaussian width ({MIN_SIGMA:g}): "
            f"nearly coincident nodes make the Gram matrix numerically singular{what} at "
            f"any sigma. Remove the duplicate or resample the shape evenly.{detail}")
    works = auto_sigma(shape, sigma_rel)
    hint = (f"the largest sigma that keeps it well conditioned here is about {works:.2g}; "
            if works < sigma_rel else "")
    return ModelError(
        f"sigma={sigma_rel:g} (x mean node spacing) is too large for this {shape.m}-node "
        f"shape: its Gaussian Gram matrix is numerically singular{what}. Use a smaller sigma "
        f"({hint}sigma=None chooses one per shape).{detail}")


def _closest_nodes(shape) -> tuple[float, int, int]:
    """The two nearest nodes of ``shape`` and their distance in mean node spacings."""
    from scipy.spatial import cKDTree

    x = shape.normalized
    dist, near = cKDTree(x).query(x, k=2)
    i = int(np.argmin(dist[:, 1]))
    j = int(near[i, 1])
    return float(dist[i, 1] / shape.spacing), min(i, j), max(i, j)
