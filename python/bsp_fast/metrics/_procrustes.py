"""Per-frame Procrustes alignment (rotation + scale + translation) for PA-MPJPE, batched.

For each frame the 3x3 matrix ``M = X0^T Y0`` (centred ground truth X0, centred prediction
Y0, both divided by their norms) is decomposed as ``M = U S V^T`` and the prediction is
mapped by ``y -> a * y R + t`` with ``R = V U^T`` and ``a = tr(S) |X0| / |Y0|``. When
``det(V U^T) < 0`` the best *proper* rotation flips the singular pair with the smallest
singular value (the reflection fix), and that singular value enters ``tr(S)`` negated.

Instead of one LAPACK call per frame, the SVD of all frames is computed at once by a
one-sided Jacobi method: the columns of ``W = M V`` are rotated in pairs until they are
orthogonal, so ``W = U S`` and ``V`` (a product of plane rotations) is a proper rotation.
The reflection fix falls out of the construction: the left vector of the smallest singular
value is the cross product of the other two (so ``U`` is proper too) and its signed singular
value is ``u . W``. Frames where this is ill-conditioned (middle singular value below 1e-10
of the largest: collinear poses) or that did not converge are redone with the library SVD.

Every step is an element-wise array operation over the frames (NumPy or torch), on
coordinate planes laid out ``(3, J, n)`` with the frame axis last, so per-frame numbers
``(n,)`` broadcast along contiguous rows.
"""
from __future__ import annotations

PAIRS = ((0, 1), (0, 2), (1, 2))
MAX_SWEEPS = 16
#: a sweep in which every pair starts with |cos(angle)| <= 1e-8 ends orthogonal to ~1e-16
#: (Jacobi converges quadratically); that sweep is the last
TOL2 = 1e-16
DEGENERATE = 1e-10


def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _rotate(cols, p, q, c, s):
    """Columns p, q of ``cols`` (lists of 3 arrays) rotated by (c, s)."""
    cp, cq = cols[p], cols[q]
    cols[p] = [c * u - s * v for u, v in zip(cp, cq)]
    cols[q] = [s * u + c * v for u, v in zip(cp, cq)]


def _jacobi(M, xp):
    """One-sided Jacobi: ``(W, V, converged)`` with ``M V = W`` (orthogonal columns);
    columns are lists of three ``(n,)`` arrays; ``M[i][k]`` is row i, column k."""
    W = [[M[i][k] for i in range(3)] for k in range(3)]
    zero = M[0][0] * 0
    V = [[zero + 1 if i == k else zero for i in range(3)] for k in range(3)]
    norm2 = [_dot3(w, w) for w in W]  # kept up to date: a' = a - t g, b' = b + t g
    converged = None
    for _ in range(MAX_SWEEPS):
        converged = None
        for p, q in PAIRS:
            a, b, g = norm2[p], norm2[q], _dot3(W[p], W[q])
            ok = g * g <= TOL2 * (a * b)
            converged = ok if converged is None else converged & ok
            d = b - a
            den = xp.abs(d) + xp.sqrt(d * d + 4 * g * g)
            t = 2 * xp.where(d >= 0, g, -g) / xp.where(den > 0, den, 1.0)
            c = 1 / xp.sqrt(1 + t * t)
            s = c * t
            _rotate(W, p, q, c, s)
            _rotate(V, p, q, c, s)
            norm2[p], norm2[q] = a - t * g, b + t * g
        if bool(converged.all()):
            break
    return W, V, converged


def _svd_rotation(M, xp):
    """``(R, tr, ok)``: the best proper rotation ``R[i][j]`` and the signed singular value
    sum, for the frames where the Jacobi result is well-conditioned (``ok``)."""
    W, V, converged = _jacobi(M, xp)
    s = [xp.sqrt(_dot3(w, w)) for w in W]
    small = [(s[0] <= s[1]) & (s[0] <= s[2])]
    small.append(~small[0] & (s[1] <= s[2]))
    small.append(~small[0] & ~small[1])
    inv = [xp.where(v > 0, 1 / xp.where(v > 0, v, 1.0), 0.0) for v in s]
    u = [[x * k for x in w] for w, k in zip(W, inv)]
    U = []
    for k in range(3):  # the smallest: completes a right-handed frame
        x = _cross(u[(k + 1) % 3], u[(k + 2) % 3])
        U.append([xp.where(small[k], xk, uk) for xk, uk in zip(x, u[k])])
    tr = _dot3(U[0], W[0]) + _dot3(U[1], W[1]) + _dot3(U[2], W[2])
    R = [[V[0][i] * U[0][j] + V[1][i] * U[1][j] + V[2][i] * U[2][j] for j in range(3)]
         for i in range(3)]
    top = xp.maximum(xp.maximum(s[0], s[1]), s[2])
    mid = s[0] + s[1] + s[2] - top - xp.minimum(xp.minimum(s[0], s[1]), s[2])
    ok = converged & ((mid > DEGENERATE * top) | (top == 0))
    return R, tr, ok


def _fallback(M, R, tr, bad, xp):
    """Library SVD with the reflection fix for the frames ``bad`` (an index array)."""
    m = xp.stack([xp.stack([M[i][k][bad] for k in range(3)], -1) for i in range(3)], -2)
    U, S, Vh = xp.linalg.svd(m)
    V = Vh.swapaxes(-1, -2)
    d = xp.linalg.det(V @ U.swapaxes(-1, -2))
    sign = xp.where(d < 0, -1.0, 1.0)
    V[..., :, 2] = V[..., :, 2] * sign[..., None]
    S[..., 2] = S[..., 2] * sign
    Rb = V @ U.swapaxes(-1, -2)
    for i in range(3):
        for j in range(3):
            R[i][j][bad] = Rb[..., i, j]
    tr[bad] = S.sum(-1)


def aligned_errors(kind, x, y):
    """Per-joint errors ``(J, n)`` of the prediction ``y`` after the optimal similarity
    onto the ground truth ``x``; both are coordinate planes ``(3, J, n)`` in float64 (see
    ``Kind.planes``) and both are overwritten."""
    xp = kind.xp
    x -= x.mean(1)[:, None]
    y -= y.mean(1)[:, None]
    nx = xp.sqrt(kind.dot(x[0], x[0]) + kind.dot(x[1], x[1]) + kind.dot(x[2], x[2]))
    ny = xp.sqrt(kind.dot(y[0], y[0]) + kind.dot(y[1], y[1]) + kind.dot(y[2], y[2]))
    nxy = nx * ny
    finite = xp.isfinite(nxy)
    inv = xp.where(finite & (nxy > 0), 1 / xp.where(nxy > 0, nxy, 1.0), 0.0)
    M = [[kind.dot(x[i], y[k]) * inv for k in range(3)] for i in range(3)]
    R, tr, ok = _svd_rotation(M, xp)
    bad = ~ok & finite
    if bool(bad.any()):
        _fallback(M, R, tr, bad.nonzero()[:, 0] if kind.torch else bad.nonzero()[0], xp)
    # a * R folded together; the translation is implicit (both are centred)
    a = xp.where(finite & (ny > 0), tr * nx / xp.where(ny > 0, ny, 1.0), float("nan"))
    a = xp.where(finite & (ny == 0), 0.0, a)
    tmp = xp.empty_like(x[0])
    for j in range(3):  # x[j] <- x[j] - (a y R)[j]
        for i in range(3):
            xp.multiply(y[i], a * R[i][j], out=tmp)
            x[j] -= tmp
    xp.multiply(x, x, out=x)
    err = x[0]
    err += x[1]
    err += x[2]
    return xp.sqrt(err, out=err)
