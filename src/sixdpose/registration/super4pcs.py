"""Super4PCS global registration (Mellado, Aiger, Mitra, SGP 2014), vectorised NumPy/SciPy.

No maintained package offers Super4PCS to Python (OpenGR's binary is what the paper used), so the
algorithm is implemented here. Outline (with the paper's notation, ``P`` = cloud the bases are drawn
from, here the masked scene; ``Q`` = cloud searched for congruent sets, here the object model):

1. Both clouds are sampled to the same spatial density, about ``n_samples`` points on ``P``.
2. A *smart index* of ``Q``: every point pair sorted by length, with the rigid invariants of the
   normals relative to the pair (``n_i.u``, ``n_j.u``, ``n_i.n_j``, ``u`` the unit pair direction).
   Extracting the pairs of length ``d +- delta`` is a binary search; the normal-angle filter is one
   vectorised comparison (Super4PCS section 5, "pair filtering with normals").
3. For each wide, nearly coplanar base ``{a, b, c, d}`` of ``P`` (diagonals ``ab`` and ``cd``
   crossing at ``e``; invariants ``r1 = |ae|/|ab|``, ``r2 = |ce|/|cd|``, angle between ``ab`` and
   ``cd``), the candidate pairs give intermediate points ``e1 = q_i + r1 (q_j - q_i)`` and
   ``e2 = q_k + r2 (q_l - q_k)``; congruent 4-point sets are the ``(e1, e2)`` within ``delta`` whose
   pair directions make the base's angle (the rigid, not just affine, congruence filter of
   Super4PCS). Matching uses a KD-tree range join, all candidates at once.
4. Each congruent set gives a rigid transform (batched Kabsch/SVD); sets whose 4-point residual or
   normal agreement fail are dropped, and the rest are verified by the *largest common pointset*
   (LCP): the fraction of sampled ``P`` points within ``delta`` of ``Q`` (with agreeing normals)
   after the transform, first on a subset, then on all samples for the best few.
5. Stop when the LCP reaches ``stop_lcp`` or after ``n_bases`` bases. Every budget counts work (bases,
   pairs, candidates, join size), never seconds, so the result does not depend on the machine's load.

No Python loop runs over candidate pairs or congruent sets; the only loop is over bases (tens).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from ..geometry import X_from

if TYPE_CHECKING:
    from .presets import RegistrationConfig


@dataclass
class Super4PCSResult:
    """Result of :func:`super4pcs`.

    Attributes:
        T: (4, 4) rigid transform mapping ``P`` onto ``Q`` (``q = R p + t``).
        lcp: largest common pointset fraction of the sampled ``P`` (0..1) of ``T``.
        n_bases: bases tried. n_congruent: congruent sets found. n_verified: sets verified.
        time: seconds.
    """

    T: np.ndarray
    lcp: float
    n_bases: int
    n_congruent: int
    n_verified: int
    time: float


def _voxel_keys(x: np.ndarray, size: float) -> np.ndarray:
    return np.floor(x / size).astype(np.int64) @ np.array([1, 1 << 20, 1 << 40], dtype=np.int64)


def voxel_subsample(x: np.ndarray, size: float, rng: np.random.Generator) -> np.ndarray:
    """Indices of one random point per occupied voxel of edge ``size`` (metres)."""
    if len(x) == 0:
        return np.zeros(0, dtype=np.int64)
    perm = rng.permutation(len(x))
    keys = _voxel_keys(x[perm] - x.min(axis=0), size)
    _, first = np.unique(keys, return_index=True)
    return np.sort(perm[first])


def density_matched_samples(
    P: np.ndarray, Q: np.ndarray, n: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, float]:
    """Sample ``P`` to about ``n`` points and ``Q`` at the same spatial density.

    A voxel edge ``s`` giving ~``n`` occupied voxels on ``P`` is found by bisection; both clouds keep
    one random point per voxel of that edge.
    Returns:
        indices into ``P``, indices into ``Q``, the voxel edge ``s`` (metres).
    """
    ext = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0))) + 1e-9
    lo, hi = ext / 1e4, ext  # voxel edges: lo gives >= n voxels (if P has them), hi gives 1
    if len(P) <= n:
        s = lo
    else:
        for _ in range(18):
            mid = math.sqrt(lo * hi)
            k = len(np.unique(_voxel_keys(P - P.min(axis=0), mid)))
            if k > n:
                lo = mid
            else:
                hi = mid
            if hi / lo < 1.03:
                break
        s = hi
    ip = voxel_subsample(P, s, rng) if len(P) > n else np.arange(len(P))
    if len(ip) > n:
        ip = np.sort(rng.choice(ip, size=n, replace=False))
    iq = voxel_subsample(Q, s, rng)
    return ip, iq, s


class PairIndex:
    """All point pairs of ``Q`` sorted by length, with their normal invariants (the smart index).

    Args:
        Q: (M, 3) points. Qn: (M, 3) unit normals.
    """

    def __init__(self, Q: np.ndarray, Qn: np.ndarray):
        i, j = np.triu_indices(len(Q), k=1)
        d = Q[j] - Q[i]
        ln = np.linalg.norm(d, axis=1)
        order = np.argsort(ln, kind="stable")
        self.i, self.j, self.len = i[order], j[order], ln[order]
        u = d[order] / np.maximum(self.len, 1e-12)[:, None]
        self.ai = np.einsum("ij,ij->i", Qn[self.i], u)  # n_i . u
        self.aj = np.einsum("ij,ij->i", Qn[self.j], u)  # n_j . u
        self.c = np.einsum("ij,ij->i", Qn[self.i], Qn[self.j])  # n_i . n_j
        self.u = u

    def ordered_pairs(self, length: float, delta: float, alpha: float, beta: float, gamma: float, tol: float):
        """Ordered pairs ``(first, second)`` with length ``length +- delta`` whose normals make the
        base pair's invariants ``(n_first.u, n_second.u, n_first.n_second) = (alpha, beta, gamma)``
        within ``tol`` (cosine units); ``tol=None`` disables the normal filter.

        Returns:
            first (K,), second (K,) int indices into ``Q``; unit directions (K, 3) first -> second.
        """
        lo, hi = np.searchsorted(self.len, [length - delta, length + delta])
        sl = slice(lo, hi)
        i, j, u = self.i[sl], self.j[sl], self.u[sl]
        if tol is None:
            fwd = np.ones(hi - lo, dtype=bool)
            bwd = fwd
        else:
            ai, aj, c = self.ai[sl], self.aj[sl], self.c[sl]
            okc = np.abs(c - gamma) < tol
            fwd = okc & (np.abs(ai - alpha) < tol) & (np.abs(aj - beta) < tol)
            bwd = okc & (np.abs(-aj - alpha) < tol) & (np.abs(-ai - beta) < tol)
        first = np.concatenate([i[fwd], j[bwd]])
        second = np.concatenate([j[fwd], i[bwd]])
        dirs = np.concatenate([u[fwd], -u[bwd]])
        return first, second, dirs


def _closest_line_params(a, b, c, d):
    """Parameters ``s, t`` of the closest points ``a + s (b - a)``, ``c + t (d - c)`` (broadcast over
    leading dims) and the gap between them; ``s = t = nan`` for parallel lines."""
    u, v, w = b - a, d - c, a - c
    A, B, C = (u * u).sum(-1), (u * v).sum(-1), (v * v).sum(-1)
    D, E = (u * w).sum(-1), (v * w).sum(-1)
    den = A * C - B * B
    with np.errstate(divide="ignore", invalid="ignore"):  # parallel lines: nan, flagged below
        s = (B * E - C * D) / den
        t = (A * E - B * D) / den
        gap = np.linalg.norm((a + s[..., None] * u) - (c + t[..., None] * v), axis=-1)
    bad = den <= 1e-12 * A * C
    s = np.where(bad, np.nan, s)
    t = np.where(bad, np.nan, t)
    return s, t, gap


def select_base(P: np.ndarray, base_dist: float, planar_tol: float, rng: np.random.Generator, n_trials: int = 64,
                width: float | None = None):
    """Pick a wide, nearly coplanar 4-point base of ``P`` whose diagonals cross.

    Args:
        P: (N, 3) sampled points. base_dist: largest wanted distance between base points (metres).
        planar_tol: largest allowed gap between the two diagonals (metres). n_trials: random triangles.
        width: the cloud's extent across its main axis (metres; None: ``base_dist``). On thin,
            elongated views (a marker, a knife, a screwdriver) the base is a thin quadrilateral: the
            triangle's area and shortest side are judged against ``min(width, base_dist)``.
    Returns:
        ``(idx (4,), r1, r2)`` with diagonals ``P[idx[0]]P[idx[1]]`` and ``P[idx[2]]P[idx[3]]``, or
        ``None`` if no valid base was found.
    """
    n = len(P)
    if n < 4:
        return None
    tri = np.stack([rng.integers(0, n, n_trials) for _ in range(3)], axis=1)
    a, b, c = P[tri[:, 0]], P[tri[:, 1]], P[tri[:, 2]]
    dab, dac, dbc = (np.linalg.norm(x - y, axis=1) for x, y in ((a, b), (a, c), (b, c)))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    w = base_dist if width is None else min(width, base_dist)
    ok = (np.maximum(np.maximum(dab, dac), dbc) <= base_dist) & (np.minimum(np.minimum(dab, dac), dbc) > 0.3 * w)
    ok &= area > 0.12 * base_dist * w
    # a random wide triangle (not the widest one: with outliers, the widest ones hold outliers)
    for k in rng.permutation(np.flatnonzero(ok))[:8]:
        ia, ib, ic = tri[k]
        A, B, C = P[ia], P[ib], P[ic]
        nrm = np.cross(B - A, C - A)
        nrm /= np.linalg.norm(nrm)
        plane = np.abs((P - A) @ nrm)
        dmin = np.min(np.stack([np.linalg.norm(P - X, axis=1) for X in (A, B, C)]), axis=0)
        cand = (plane < planar_tol) & (dmin > 0.25 * w) & (np.linalg.norm(P - A, axis=1) <= base_dist)
        if not cand.any():
            continue
        X = P[cand]
        best = None
        # the three ways to split {A, B, C, X} into two crossing diagonals
        for (p1, p2, p3), order in (((A, B, C), (ia, ib, ic)), ((A, C, B), (ia, ic, ib)), ((B, C, A), (ib, ic, ia))):
            s, t, gap = _closest_line_params(p1[None], p2[None], p3[None], X)
            valid = (s > 0.1) & (s < 0.9) & (t > 0.1) & (t < 0.9) & (gap < planar_tol)
            if not valid.any():
                continue
            # prefer the widest second diagonal
            w = np.where(valid, np.linalg.norm(X - p3, axis=1), -1.0)
            m = int(np.argmax(w))
            if best is None or w[m] > best[0]:
                best = (w[m], (order[0], order[1], order[2], int(np.flatnonzero(cand)[m])), float(s[m]), float(t[m]))
        if best is not None:
            return np.array(best[1]), best[2], best[3]
    return None


def kabsch_batch(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid transforms minimising ``sum |R src_k + t - dst_k|^2``, batched.

    Args:
        src: (K, 3) or (M, K, 3). dst: (M, K, 3).
    Returns:
        R (M, 3, 3) proper rotations, t (M, 3).
    """
    if src.ndim == 2:
        src = np.broadcast_to(src, dst.shape)
    cs, cd = src.mean(axis=1), dst.mean(axis=1)
    H = np.einsum("mki,mkj->mij", src - cs[:, None], dst - cd[:, None])
    U, _, Vt = np.linalg.svd(H)
    det = np.sign(np.linalg.det(np.einsum("mji,mkj->mik", Vt, U)))
    D = np.ones((len(H), 3))
    D[:, 2] = det
    R = np.einsum("mji,mj,mkj->mik", Vt, D, U)
    t = cd - np.einsum("mij,mj->mi", R, cs)
    return R, t


def super4pcs(
    P: np.ndarray,
    Pn: np.ndarray | None,
    Q: np.ndarray,
    Qn: np.ndarray | None,
    cfg: RegistrationConfig | None = None,
    *,
    delta: float | None = None,
    Q_verify: np.ndarray | None = None,
    Qn_verify: np.ndarray | None = None,
) -> Super4PCSResult:
    """Register ``P`` onto ``Q`` with Super4PCS (normals optional).

    Args:
        P: (N, 3) source points (metres), e.g. the masked scene cloud. Pn: (N, 3) unit normals or None.
        Q: (M, 3) target points, e.g. the object model. Qn: (M, 3) unit normals or None.
        cfg: a :class:`~sixdpose.registration.presets.RegistrationConfig` (default: the ``default``
            preset); its ``s4pcs_*`` fields are the algorithm's parameters and ``seed`` its random
            seed (the result is deterministic for a given seed):

            * ``s4pcs_overlap``: expected fraction of ``P`` lying on ``Q`` (paper: 0.7); sets the base
              width (overlap x the extent of ``P``) and the number of bases;
            * ``s4pcs_samples``: points sampled on ``P`` (paper: 200); ``Q`` is sampled at the same
              density, at most ``s4pcs_max_q`` of them (random subset);
            * ``s4pcs_bases``: bases to try (None: enough to draw one all-inlier base with 99.9 %
              probability, ``ceil(log(0.001) / log(1 - overlap^4))``);
            * ``s4pcs_max_time``: ignored (it was a wall-clock limit, which made the result depend on
              the machine's load; kept so that older configs load);
            * ``s4pcs_normal_tol_deg``: normal-angle tolerance for pair filtering and set
              verification (None: normals unused);
            * ``s4pcs_stop_lcp``: stop as soon as a transform reaches this LCP;
            * ``s4pcs_max_candidates``: congruent sets scored per base (random subset);
            * ``s4pcs_max_pairs``: candidate pairs per base diagonal (random subset);
            * ``s4pcs_pair_tol_factor``: pair-length and intermediate-point tolerance is
              ``max(delta, factor x sample spacing)``;
            * ``s4pcs_join_budget``: intermediate-point matches materialised per base (random
              thinning of both pair sets; None: 20 x ``s4pcs_max_candidates``); bounds time and memory.
        delta: registration accuracy in metres (pair length, intermediate point and LCP tolerance;
            paper: 0.01). None: ``cfg.s4pcs_delta``. (The pipeline passes ``s4pcs_delta_rel`` x the
            object diameter when that is set.)
        Q_verify, Qn_verify: denser target cloud for the LCP (default: ``Q``).
    Returns:
        :class:`Super4PCSResult` with ``T`` mapping ``P`` onto ``Q`` (identity and lcp 0 on failure).
    """
    if cfg is None:
        from .presets import PRESETS

        cfg = PRESETS["default"]
    overlap, n_samples, n_bases = cfg.s4pcs_overlap, cfg.s4pcs_samples, cfg.s4pcs_bases
    normal_tol_deg, stop_lcp = cfg.s4pcs_normal_tol_deg, cfg.s4pcs_stop_lcp
    max_candidates, max_pairs, pair_tol_factor = (
        cfg.s4pcs_max_candidates,
        cfg.s4pcs_max_pairs,
        cfg.s4pcs_pair_tol_factor,
    )
    max_q, join_budget, seed = cfg.s4pcs_max_q, cfg.s4pcs_join_budget, cfg.seed
    delta = cfg.s4pcs_delta if delta is None else float(delta)
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    P = np.asarray(P, dtype=np.float64)
    Q = np.asarray(Q, dtype=np.float64)
    use_n = normal_tol_deg is not None and Pn is not None and Qn is not None
    fail = Super4PCSResult(np.eye(4), 0.0, 0, 0, 0, 0.0)
    if len(P) < 4 or len(Q) < 4:
        fail.time = time.perf_counter() - t0
        return fail
    if join_budget is None:
        join_budget = 20 * max_candidates
    if n_bases is None:
        f4 = min(max(overlap, 0.05), 0.999) ** 4
        n_bases = int(math.ceil(math.log(1e-3) / math.log(1.0 - f4)))
    ip, iq, spacing = density_matched_samples(P, Q, n_samples, rng)
    if max_q is not None and len(iq) > max_q:
        # the smart index holds every pair of Q's samples (O(len(iq)^2)): when P covers a small part
        # of a large model, thin Q's samples at random to bound that cost
        iq = np.sort(rng.choice(iq, size=max_q, replace=False))
    # both clouds are sampled independently: a sample of Q can be up to ~spacing away from the point
    # matching a base point, so the pair tolerances cannot be tighter than that
    tol = max(delta, pair_tol_factor * spacing)
    Ps, Qs = P[ip], Q[iq]
    Psn = Pn[ip] if use_n else None
    Qsn = Qn[iq] if use_n else np.zeros_like(Qs)
    index = PairIndex(Qs, Qsn)
    Qv = Q if Q_verify is None else np.asarray(Q_verify, dtype=np.float64)
    Qvn = (Qn if Q_verify is None else Qn_verify) if use_n else None
    tree = cKDTree(Qv)
    ntol = math.sin(math.radians(normal_tol_deg)) * 1.2 if use_n else None
    ncos = math.cos(math.radians(normal_tol_deg)) if use_n else None
    ver_cos = math.cos(math.radians(max(2 * normal_tol_deg, 45.0))) if use_n else None
    # base width: overlap x the (robust) extent of P, and never wider than Q itself
    ext = 2.0 * float(np.percentile(np.linalg.norm(Ps - np.median(Ps, axis=0), axis=1), 90))
    q_ext = 2.0 * float(np.max(np.linalg.norm(Qs - Qs.mean(axis=0), axis=1)))
    base_dist = max(overlap * min(ext, q_ext), 4 * delta)
    # extent across the main axis (second principal direction), for thin elongated views
    Pc = Ps - np.median(Ps, axis=0)
    ax2 = np.linalg.svd(Pc - Pc.mean(axis=0), full_matrices=False)[2][1]
    width = max(overlap * 2.0 * float(np.percentile(np.abs(Pc @ ax2), 90)), 2 * delta)
    sub = rng.choice(len(Ps), size=min(len(Ps), 48), replace=False)

    def lcp(R, t, idx):
        """Fraction of Ps[idx] within delta of Qv after (R, t) (normals agreeing); shapes (M,)."""
        X = np.einsum("mij,kj->mki", R, Ps[idx]) + t[:, None, :]
        d, nn = tree.query(X.reshape(-1, 3), k=1, distance_upper_bound=delta)
        ok = np.isfinite(d)
        if use_n:
            Xn = np.einsum("mij,kj->mki", R, Psn[idx]).reshape(-1, 3)
            nnc = np.minimum(nn, len(Qv) - 1)
            ok &= np.einsum("ij,ij->i", Xn, Qvn[nnc]) > ver_cos
        return ok.reshape(len(R), len(idx)).mean(axis=1)

    best = (0.0, np.eye(3), np.zeros(3))
    n_cong = n_ver = tried = 0
    for _ in range(n_bases):
        base = select_base(Ps, base_dist, planar_tol=max(delta * 0.5, 1e-4), rng=rng, width=width)
        if base is None:
            continue
        tried += 1
        idx, r1, r2 = base
        a, b, c, d = Ps[idx]
        d1, d2 = np.linalg.norm(b - a), np.linalg.norm(d - c)
        u1, u2 = (b - a) / d1, (d - c) / d2
        cosphi = float(u1 @ u2)
        if use_n:
            na, nb, nc, nd = Psn[idx]
            f1, s1, w1 = index.ordered_pairs(d1, tol, na @ u1, nb @ u1, na @ nb, ntol)
            f2, s2, w2 = index.ordered_pairs(d2, tol, nc @ u2, nd @ u2, nc @ nd, ntol)
        else:
            f1, s1, w1 = index.ordered_pairs(d1, tol, 0, 0, 0, None)
            f2, s2, w2 = index.ordered_pairs(d2, tol, 0, 0, 0, None)
        if len(f1) == 0 or len(f2) == 0:
            continue
        if len(f1) > max_pairs:
            sel = rng.choice(len(f1), size=max_pairs, replace=False)
            f1, s1, w1 = f1[sel], s1[sel], w1[sel]
        if len(f2) > max_pairs:
            sel = rng.choice(len(f2), size=max_pairs, replace=False)
            f2, s2, w2 = f2[sel], s2[sel], w2[sel]
        e1 = Qs[f1] + r1 * (Qs[s1] - Qs[f1])
        e2 = Qs[f2] + r2 * (Qs[s2] - Qs[f2])
        t1, t2 = cKDTree(e1), cKDTree(e2)
        # on spheres and other near-symmetric shapes almost every (e1, e2) pair matches: count the join
        # first and thin both sides at random so that at most ``join_budget`` pairs are materialised
        # (a random subset, as the max_candidates cap below takes anyway); without this one base of
        # the baseball with the paper's delta took 28 s and 6 GB
        # (the join cannot exceed len(e1) * len(e2): only count when that could pass the budget)
        n_join = int(t1.count_neighbors(t2, tol)) if len(e1) * len(e2) > join_budget else 0
        if n_join > join_budget:
            keep_f = math.sqrt(join_budget / n_join)
            m1 = rng.random(len(e1)) < keep_f
            m2 = rng.random(len(e2)) < keep_f
            f1, s1, w1, e1 = f1[m1], s1[m1], w1[m1], e1[m1]
            f2, s2, w2, e2 = f2[m2], s2[m2], w2[m2], e2[m2]
            if len(e1) == 0 or len(e2) == 0:
                continue
            t1, t2 = cKDTree(e1), cKDTree(e2)
        sm = t1.sparse_distance_matrix(t2, tol, output_type="ndarray")
        if len(sm) == 0:
            continue
        k1, k2 = sm["i"], sm["j"]
        # rigid congruence: the two diagonals must make the base's angle
        ang_tol = 2.0 * tol / min(d1, d2) + 0.05
        dphi = np.abs(
            np.arccos(np.clip(np.einsum("ij,ij->i", w1[k1], w2[k2]), -1, 1)) - math.acos(np.clip(cosphi, -1, 1))
        )
        keep = dphi < ang_tol
        k1, k2 = k1[keep], k2[keep]
        if len(k1) == 0:
            continue
        if len(k1) > max_candidates:
            sel = rng.choice(len(k1), size=max_candidates, replace=False)
            k1, k2 = k1[sel], k2[sel]
        n_cong += len(k1)
        quad = np.stack([f1[k1], s1[k1], f2[k2], s2[k2]], axis=1)  # (M, 4) indices into Qs
        src = np.stack([a, b, c, d])
        dst = Qs[quad]
        R, t = kabsch_batch(src, dst)
        res = np.linalg.norm(np.einsum("mij,kj->mki", R, src) + t[:, None] - dst, axis=2).max(axis=1)
        ok = res < tol
        if use_n:
            rn = np.einsum("mij,kj->mki", R, Psn[idx])
            ok &= (np.einsum("mki,mki->mk", rn, Qsn[quad]) > ncos).all(axis=1)
        if not ok.any():
            continue
        R, t = R[ok], t[ok]
        n_ver += len(R)
        # verification cascade: 12 samples for all, 48 for the best 5%, all samples for the best 8
        score = lcp(R, t, sub[:12])
        keep = np.argsort(-score)[: max(64, len(R) // 20)]
        keep = keep[score[keep] >= score[keep[0]] - 0.25]
        R, t = R[keep], t[keep]
        score = lcp(R, t, sub)
        top = np.argsort(-score)[:8]
        s_full = lcp(R[top], t[top], np.arange(len(Ps)))
        k = int(np.argmax(s_full))
        if s_full[k] > best[0]:
            best = (float(s_full[k]), R[top[k]], t[top[k]])
        if best[0] >= stop_lcp:
            break
    return Super4PCSResult(X_from(best[1], best[2]), best[0], tried, n_cong, n_ver, time.perf_counter() - t0)
