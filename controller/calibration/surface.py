"""Surface model from a point cloud: PLY (ascii), XYZ text or NPZ; normals by local plane fit
(radius 1.5 x mean point spacing) when absent; analytic sphere least-squares fit."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from ..errors import InputError


def _read_ply(path: Path) -> np.ndarray:
    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            raise InputError(f"{path}: not a PLY file")
        props: list[str] = []
        n: int | None = None
        fmt: str | None = None
        in_vertex = False
        while True:
            line = f.readline()
            if not line:
                raise InputError(f"{path}: PLY header without end_header")
            tok = line.decode("ascii", "replace").split()
            if not tok:
                continue
            if tok[0] == "format":
                fmt = tok[1]
            elif tok[0] == "element":
                in_vertex = tok[1] == "vertex"
                if in_vertex:
                    n = int(tok[2])
            elif tok[0] == "property" and in_vertex:
                props.append(tok[-1])
            elif tok[0] == "end_header":
                break
        if n is None:
            raise InputError(f"{path}: PLY header without a vertex element")
        if fmt == "ascii":
            data = np.loadtxt(f, max_rows=n, ndmin=2)
        elif fmt == "binary_little_endian":
            data = np.frombuffer(f.read(n * 4 * len(props)), "<f4").reshape(n, len(props)).astype(float)
        else:
            raise InputError(f"{path}: PLY format {fmt!r} not supported (ascii, binary_little_endian float)")
    if data.shape[0] != n:
        raise InputError(f"{path}: expected {n} vertices, read {data.shape[0]}")
    cols = {p: i for i, p in enumerate(props)}
    try:
        xyz = data[:, [cols["x"], cols["y"], cols["z"]]]
    except KeyError:
        raise InputError(f"{path}: PLY vertices need x, y, z properties") from None
    if all(k in cols for k in ("nx", "ny", "nz")):
        return np.hstack([xyz, data[:, [cols["nx"], cols["ny"], cols["nz"]]]])
    return xyz


def read_cloud(path: str | Path) -> tuple[np.ndarray, np.ndarray | None]:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: point cloud not found")
    suf = path.suffix.lower()
    try:
        if suf == ".ply":
            a = _read_ply(path)
        elif suf == ".npz":
            z = np.load(path)
            a = z["points"] if "points" in z else z[z.files[0]]
            if "normals" in z:
                a = np.hstack([a, z["normals"]])
        else:
            a = np.loadtxt(path, ndmin=2, delimiter=None)
    except (ValueError, OSError, IndexError, KeyError) as exc:
        raise InputError(f"{path}: cannot read point cloud ({exc})") from None
    if a.ndim != 2 or a.shape[1] < 3 or a.shape[0] < 10:
        raise InputError(f"{path}: expected >= 10 points with x y z [nx ny nz]")
    a = a[:, :6].astype(float)
    bad = np.flatnonzero(~np.isfinite(a).all(axis=1))
    if bad.size:  # a NaN or inf sends LAPACK into an endless loop
        raise InputError(f"{path}: point {bad[0] + 1}: not finite ({bad.size} such point(s))")
    pts = a[:, :3]
    if np.linalg.matrix_rank(pts - pts.mean(0), tol=1e-9) < 3:
        raise InputError(f"{path}: the points lie on a plane or a line: not a surface scan")
    nrm = a[:, 3:6] if a.shape[1] >= 6 else None
    return pts, nrm


def estimate_normals(pts: np.ndarray, radius_factor: float = 1.5, outward_from=None) -> np.ndarray:
    """Normals by local plane fit within ``radius_factor`` x mean nearest-neighbour spacing,
    oriented away from ``outward_from`` (default: the cloud's centroid)."""
    tree = cKDTree(pts)
    dd, _ = tree.query(pts, k=2)
    spacing = float(np.mean(dd[:, 1]))
    radius = radius_factor * spacing
    nbrs = tree.query_ball_point(pts, radius)
    nrm = np.zeros_like(pts)
    for i, idx in enumerate(nbrs):
        if len(idx) < 3:
            idx = tree.query(pts[i], k=6)[1]
        q = pts[idx] - pts[idx].mean(0)
        _, _, vt = np.linalg.svd(q, full_matrices=False)
        nrm[i] = vt[-1]
    ref = np.asarray(outward_from, float) if outward_from is not None else pts.mean(0)
    flip = np.sum(nrm * (pts - ref), 1) < 0
    nrm[flip] *= -1
    return nrm


def load_cloud(path) -> tuple[np.ndarray, np.ndarray]:
    pts, nrm = read_cloud(path)
    if nrm is None:
        c, _, _ = fit_sphere_points(pts)
        nrm = estimate_normals(pts, outward_from=c)
    nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    return pts, nrm


def fit_sphere_points(pts: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Least-squares sphere: algebraic start, geometric (radial residual) refinement.
    Returns (centre, radius, residual RMSE in metres)."""
    A = np.hstack([2 * pts, np.ones((len(pts), 1))])
    b = np.sum(pts**2, 1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    c0 = sol[:3]
    r0 = float(np.sqrt(sol[3] + c0 @ c0))
    res = least_squares(lambda p: np.linalg.norm(pts - p[:3], axis=1) - p[3], np.r_[c0, r0], method="lm")
    c, r = res.x[:3], float(res.x[3])
    rmse = float(np.sqrt(np.mean(res.fun**2)))
    return c, r, rmse


@dataclass
class SphereFit:
    center: np.ndarray
    radius: float
    rmse_m: float
    n_points: int


def fit_sphere(path) -> SphereFit:
    pts, _ = read_cloud(path)
    c, r, rmse = fit_sphere_points(pts)
    return SphereFit(c, r, rmse, len(pts))


# --- beyond the paper: sphere + low-order radial polynomial (shape imperfection) ------------
def _monomials(degree: int) -> list[tuple[int, int, int]]:
    return [(a, b, d - a - b) for d in range(degree + 1) for a in range(d + 1) for b in range(d - a + 1)]


def radial_poly_eval(u: np.ndarray, coeffs, degree: int, grad: bool = True):
    """h(u) = sum c_k x^a y^b z^c on unit directions u (...,3) and its 3-D gradient (None
    with ``grad=False``: the surface map's first passes need the height only)."""
    u = np.asarray(u, float)
    x, y, z = u[..., 0], u[..., 1], u[..., 2]
    h = np.zeros(u.shape[:-1])
    g = np.zeros(u.shape) if grad else None
    pw = {}

    def p(v, k, key):
        if (key, k) not in pw:
            pw[(key, k)] = v**k if k > 0 else np.ones_like(v)
        return pw[(key, k)]

    for c, (a, b, d) in zip(coeffs, _monomials(degree)):
        if c == 0:
            continue
        xa, yb, zd = p(x, a, "x"), p(y, b, "y"), p(z, d, "z")
        h += c * xa * yb * zd
        if g is None:
            continue
        if a:
            g[..., 0] += c * a * p(x, a - 1, "x") * yb * zd
        if b:
            g[..., 1] += c * b * xa * p(y, b - 1, "y") * zd
        if d:
            g[..., 2] += c * d * xa * yb * p(z, d - 1, "z")
    return h, g


def fit_radial_poly(pts: np.ndarray, center, radius: float, degree: int = 6):
    """Least-squares radial deviation r(u) - radius as a polynomial in u (degree <= ``degree``);
    returns (coeffs, residual RMSE m).  Captures low-order bumps the sphere misses."""
    d = pts - np.asarray(center, float)
    r = np.linalg.norm(d, axis=1)
    u = d / r[:, None]
    mons = _monomials(degree)
    A = np.stack([u[:, 0] ** a * u[:, 1] ** b * u[:, 2] ** c for a, b, c in mons], axis=1)
    coef, *_ = np.linalg.lstsq(A, r - radius, rcond=1e-10)
    res = A @ coef - (r - radius)
    return coef, float(np.sqrt(np.mean(res**2)))
