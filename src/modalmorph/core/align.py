"""Horn's closed-form similarity between corresponding point sets (method.md §3).

Horn (1987), "Closed-form solution of absolute orientation using unit quaternions": centre
both sets, form the cross-covariance ``S`` and the symmetric 4 x 4 matrix ``N``; the
rotation is the unit quaternion of ``N``'s largest eigenvalue, the symmetric scale is
``s = sqrt(sum |r'_r|^2 / sum |r'_l|^2)`` and the translation ``t = mean_r - s R mean_l``.
A 2D problem is the 3D one with ``z = 0``, restricted to rotations about ``z``; so the
result is always a proper rotation, never a reflection.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import OptionError, ShapeError

__all__ = ["Similarity", "align"]

# Source points whose spread is at most this fraction of their magnitude coincide (a few
# float64 roundings: 1e-16 relative).
_COINCIDE = 1e-14


@dataclass(frozen=True, eq=False, repr=False)
class Similarity:
    """The map ``x -> scale * rotation @ x + translation``.

    Attributes
    ----------
    rotation : ndarray, shape (d, d)
        Proper rotation (orthogonal, determinant +1).
    scale : float
        Positive scale factor.
    translation : ndarray, shape (d,)
    """

    rotation: np.ndarray
    scale: float
    translation: np.ndarray

    def __repr__(self) -> str:
        d = len(self.translation)
        turn = np.degrees(np.arctan2(self.rotation[1, 0], self.rotation[0, 0]))
        angle = f", rotation {turn:.3g} deg" if d == 2 else ""
        return (f"Similarity({d}D, scale {self.scale:.6g}{angle}, translation "
                f"{np.array2string(np.asarray(self.translation), precision=4)})")

    @property
    def dim(self) -> int:
        return self.rotation.shape[0]

    @property
    def angle(self) -> float:
        """The rotation's angle in degrees, 0-180 (about its axis in 3D)."""
        cos = (np.trace(self.rotation) - (self.dim - 2)) / 2  # trace: d - 2 + 2 cos
        return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))

    @property
    def matrix(self) -> np.ndarray:
        """Homogeneous matrix, shape (d + 1, d + 1)."""
        d = self.dim
        out = np.eye(d + 1)
        out[:d, :d] = self.scale * self.rotation
        out[:d, d] = self.translation
        return out

    def apply(self, points) -> np.ndarray:
        """Transform points of shape (m, d) (or one point (d,)); returns the same shape.

        Raises ShapeError (a ValueError) if ``points`` are not finite or their images
        overflow float64.
        """
        p = np.asarray(points, dtype=np.float64)
        if p.ndim not in (1, 2) or p.shape[-1] != self.dim:
            raise ShapeError(f"points must have {self.dim} coordinates per row, got "
                             f"shape {p.shape}")
        if not np.isfinite(p).all():
            raise ShapeError("points must be finite (no NaN or inf)")
        with np.errstate(over="ignore", invalid="ignore"):
            out = self.scale * p @ self.rotation.T + self.translation
        if not np.isfinite(out).all():
            raise ShapeError("the transformed points overflow float64")
        return out

    def inverse(self) -> Similarity:
        """The similarity that undoes this one.

        Raises ShapeError (a ValueError) if its scale or translation overflow float64.
        """
        rt = self.rotation.T
        with np.errstate(over="ignore", invalid="ignore"):
            scale, translation = 1.0 / self.scale, -(rt @ self.translation) / self.scale
        if not (np.isfinite(scale) and np.isfinite(translation).all()):
            raise ShapeError(f"the inverse of a similarity of scale {self.scale:.3g} and "
                             f"translation {self.translation} overflows float64")
        return Similarity(rotation=rt, scale=scale, translation=translation)

    def part(self, w: float, centre) -> Similarity:
        """The fraction ``w`` (0: the identity, 1: this similarity) of this similarity
        about ``centre``: its turn by ``w`` of its angle about the same axis, its scale to
        the power ``w``, ``centre`` moved ``w`` of the way to its image."""
        c = np.asarray(centre, dtype=np.float64)
        if self.dim == 2:
            turn = w * np.arctan2(self.rotation[1, 0], self.rotation[0, 0])
            rotation = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
        else:
            from scipy.spatial.transform import Rotation

            rotation = Rotation.from_rotvec(
                w * Rotation.from_matrix(self.rotation).as_rotvec()).as_matrix()
        scale = self.scale ** w
        moved = c + w * (self.apply(c) - c)
        return Similarity(rotation=rotation, scale=scale,
                          translation=moved - scale * rotation @ c)

    @classmethod
    def identity(cls, dim: int) -> Similarity:
        return cls(rotation=np.eye(dim), scale=1.0, translation=np.zeros(dim))


def _quaternion_matrix(S: np.ndarray) -> np.ndarray:
    """Horn's symmetric 4 x 4 matrix N from the 3 x 3 cross-covariance S."""
    (sxx, sxy, sxz), (syx, syy, syz), (szx, szy, szz) = S.tolist()  # floats: the same sums
    return np.array([
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ])


def _rotation_from_quaternion(q: np.ndarray) -> np.ndarray:
    q0, qx, qy, qz = (q / np.linalg.norm(q)).tolist()
    return np.array([
        [q0**2 + qx**2 - qy**2 - qz**2, 2 * (qx * qy - q0 * qz), 2 * (qx * qz + q0 * qy)],
        [2 * (qy * qx + q0 * qz), q0**2 - qx**2 + qy**2 - qz**2, 2 * (qy * qz - q0 * qx)],
        [2 * (qz * qx - q0 * qy), 2 * (qz * qy + q0 * qx), q0**2 - qx**2 - qy**2 + qz**2],
    ])


def align(source_points, target_points, *, scale: bool = True,
          rotate: bool = True) -> Similarity:
    """Similarity that best maps ``source_points`` onto ``target_points`` (Horn, 1987).

    Minimises ``sum |target_i - (s R source_i + t)|^2`` over proper rotations ``R`` (the
    scale is Horn's symmetric one, exact when the sets are similar).

    Parameters
    ----------
    source_points, target_points : array_like, shape (k, d)
        Corresponding points (row ``i`` of one matches row ``i`` of the other), ``d`` in
        {2, 3}, ``k >= 2``.
    scale : bool, optional
        Estimate the scale (default); ``False`` fixes it at 1 (a rigid motion).
    rotate : bool, optional
        Estimate the rotation (default); ``False`` fixes it at the identity (translation
        and scale only, for objects known to share one frame).

    Returns
    -------
    Similarity

    Raises
    ------
    ShapeError
        If the arrays differ in shape, are not (k, 2) or (k, 3), are not finite, have fewer
        than 2 points, the source points all coincide, or the similarity overflows float64
        (target and source sizes more than ~1e308 apart).
    OptionError
        If ``scale`` is not a bool.
    """
    if not isinstance(scale, bool | np.bool_):
        raise OptionError(f"scale must be True or False, got {scale!r}")
    left, right = _corresponding(source_points, target_points)
    d = left.shape[1]
    # Centred (section 5.2), each set divided by its largest centred coordinate so that no
    # square over- or underflows; the scale is put back in ``s`` below.
    mean_l, mean_r = _mean(left), _mean(right)
    cl, cr = left - mean_l, right - mean_r
    if not (np.isfinite(cl).all() and np.isfinite(cr).all()):
        raise ShapeError("source_points or target_points span more than float64 can hold")
    unit_l, unit_r = np.abs(cl).max(), np.abs(cr).max()
    if unit_l <= _COINCIDE * np.abs(left).max():
        raise ShapeError("source_points all coincide: the similarity is undetermined")
    cl = cl / unit_l
    cr = cr / unit_r if unit_r > 0 else cr
    norm_l, norm_r = np.add.reduce(cl**2, axis=None), np.add.reduce(cr**2, axis=None)
    R = _rotation(cl, cr) if rotate else np.eye(d)
    with np.errstate(over="ignore", invalid="ignore"):
        s = float(np.sqrt(norm_r / norm_l) * (unit_r / unit_l)) if scale else 1.0  # symmetric
        t = mean_r - s * R @ mean_l
    if not (np.isfinite(s) and s > 0 and np.isfinite(t).all()):
        raise ShapeError(f"the similarity overflows float64 (scale {s:.3g}): source_points and "
                         f"target_points differ too much in size or position")
    return Similarity(rotation=R, scale=s, translation=t)


def _corresponding(source_points, target_points) -> tuple[np.ndarray, np.ndarray]:
    """Both point sets as float arrays (k, d), checked as :func:`align` documents."""
    for name, a in (("source_points", source_points), ("target_points", target_points)):
        if np.iscomplexobj(a):
            raise ShapeError(f"{name} must be real coordinates, got complex numbers")
    left = np.asarray(source_points, dtype=np.float64)
    right = np.asarray(target_points, dtype=np.float64)
    for name, a in (("source_points", left), ("target_points", right)):
        if a.ndim != 2 or a.shape[1] not in (2, 3):
            raise ShapeError(f"{name} must have shape (k, 2) or (k, 3), got {a.shape}")
        if not np.isfinite(a).all():
            raise ShapeError(f"{name} must be finite (no NaN or inf)")
    if left.shape != right.shape:
        raise ShapeError(f"source_points and target_points must have the same shape, got "
                         f"{left.shape} and {right.shape}")
    if len(left) < 2:
        raise ShapeError(f"align needs at least 2 corresponding points, got {len(left)}")
    return left, right


def _mean(a: np.ndarray) -> np.ndarray:
    """Column means without overflow for coordinates near the float64 limit."""
    big = np.abs(a).max()  # the sum over rows / k: np.mean's numbers, without its wrapper
    return np.add.reduce(a, axis=0) / len(a) if big < 1e300 else \
        np.add.reduce(a / big, axis=0) / len(a) * big


def _rotation(cl: np.ndarray, cr: np.ndarray) -> np.ndarray:
    """Horn's rotation (d, d) between centred corresponding points (k, d)."""
    k, d = cl.shape
    if d == 2:  # embed with z = 0
        z = np.zeros((k, 1))
        cl3, cr3 = np.concatenate([cl, z], axis=1), np.concatenate([cr, z], axis=1)
    else:
        cl3, cr3 = cl, cr
    S = cl3.T @ cr3  # S_ab = sum l_a r_b
    if d == 2:  # rotations about z only: quaternions (q0, 0, 0, qz); no reflections
        (sxx, sxy, _), (syx, syy, _), (_, _, szz) = S.tolist()  # N's entries used, as N has them
        sub = np.array([[sxx + syy + szz, sxy - syx], [sxy - syx, -sxx - syy + szz]])
        _, vec = np.linalg.eigh(sub)
        q = np.array([vec[0, -1], 0.0, 0.0, vec[1, -1]])
    else:
        _, vec = np.linalg.eigh(_quaternion_matrix(S))
        q = vec[:, -1]  # eigenvector of the largest eigenvalue
    return _rotation_from_quaternion(q)[:d, :d]
