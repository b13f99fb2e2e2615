"""Rotations and plane geometry for the stub's tasks, batched over leading axes.

Quaternions are (w, x, y, z), MuJoCo's order; rotation matrices act on column vectors. Every task
that needs one of these imports it from here, so each formula is written once.
"""
from __future__ import annotations

import mujoco
import numpy as np


# --- quaternions ----------------------------------------------------------------------------------
def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (w, x, y, z) [..., 4]."""
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = aw * bw - ax * bx - ay * by - az * bz
    out[..., 1] = aw * bx + ax * bw + ay * bz - az * by
    out[..., 2] = aw * by - ax * bz + ay * bw + az * bx
    out[..., 3] = aw * bz + ax * by - ay * bx + az * bw
    return out


def quat_conj(q: np.ndarray) -> np.ndarray:
    """The conjugate (the inverse of a unit quaternion) [..., 4]."""
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (rad) of the rotation between unit quaternions a and b [..., 4]."""
    dot = np.abs((a * b).sum(axis=-1))
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))


def quat_matrix(q: np.ndarray) -> np.ndarray:
    """[n, 3, 3] rotation matrices of unit quaternions (w, x, y, z) [n, 4]."""
    w, x, y, z = (q[:, i] for i in range(4))
    return np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                     2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                     2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1).reshape(-1, 3, 3)


def matrix_quat(matrices: np.ndarray) -> np.ndarray:
    """[n, 4] unit quaternions, w >= 0, of rotation matrices [n, 3, 3] (MuJoCo's conversion)."""
    out = np.empty((len(matrices), 4))
    for i, m in enumerate(matrices):
        mujoco.mju_mat2Quat(out[i], m.reshape(9))
    return np.where(out[:, :1] < 0, -out, out)


# --- joint angles and axis-angle -----------------------------------------------------------------
def euler_to_matrix(e: np.ndarray) -> np.ndarray:
    """[..., 3] x-y-z joint angles -> [..., 3, 3] R = Rx(a) Ry(b) Rz(c) (MuJoCo's order for three
    hinges in one body)."""
    ca, cb, cc = np.cos(e[..., 0]), np.cos(e[..., 1]), np.cos(e[..., 2])
    sa, sb, sc = np.sin(e[..., 0]), np.sin(e[..., 1]), np.sin(e[..., 2])
    r = np.empty(e.shape[:-1] + (3, 3))
    r[..., 0, 0], r[..., 0, 1], r[..., 0, 2] = cb * cc, -cb * sc, sb
    r[..., 1, 0] = ca * sc + sa * sb * cc
    r[..., 1, 1] = ca * cc - sa * sb * sc
    r[..., 1, 2] = -sa * cb
    r[..., 2, 0] = sa * sc - ca * sb * cc
    r[..., 2, 1] = sa * cc + ca * sb * sc
    r[..., 2, 2] = ca * cb
    return r


def matrix_to_euler(r: np.ndarray) -> np.ndarray:
    """Inverse of ``euler_to_matrix`` for |b| < 90 deg."""
    return np.stack([np.arctan2(-r[..., 1, 2], r[..., 2, 2]),
                     np.arcsin(np.clip(r[..., 0, 2], -1.0, 1.0)),
                     np.arctan2(-r[..., 0, 1], r[..., 0, 0])], axis=-1)


def euler_to_quat(e: np.ndarray) -> np.ndarray:
    """[..., 3] x-y-z joint angles -> [..., 4] quaternion (w, x, y, z) of Rx Ry Rz, w >= 0."""
    h = 0.5 * e
    ca, cb, cc = np.cos(h[..., 0]), np.cos(h[..., 1]), np.cos(h[..., 2])
    sa, sb, sc = np.sin(h[..., 0]), np.sin(h[..., 1]), np.sin(h[..., 2])
    pw, px, py, pz = ca * cb, sa * cb, ca * sb, sa * sb  # qx(a) * qy(b)
    q = np.stack([pw * cc - pz * sc, px * cc + py * sc, py * cc - px * sc, pz * cc + pw * sc], axis=-1)
    return np.where(q[..., :1] < 0, -q, q)


def axis_angle_matrix(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues: unit axis [..., 3], angle [...] -> [..., 3, 3]."""
    c, s = np.cos(angle)[..., None, None], np.sin(angle)[..., None, None]
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    k = np.zeros(axis.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -z, y, -x
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = z, -y, x
    return np.eye(3) * c + s * k + (1.0 - c) * axis[..., :, None] * axis[..., None, :]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for [..., 3] arrays (np.cross's axis handling costs more than the product here)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


# --- polygons in the plane -----------------------------------------------------------------------
def convex_hull(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise hull of 2-D points [k, 2] (Andrew's monotone chain)."""
    pts = sorted(map(tuple, np.round(points, 12)))
    turn = lambda o, a, b: (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])  # noqa: E731
    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and turn(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and turn(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def polygon_centroid(hull: np.ndarray) -> np.ndarray:
    """Area centroid of a counter-clockwise polygon [k, 2]."""
    x, y = hull[:, 0], hull[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    area_twice = x * yn - xn * y
    area = area_twice.sum() / 2.0
    return np.array([((x + xn) * area_twice).sum(), ((y + yn) * area_twice).sum()]) / (6.0 * area)
