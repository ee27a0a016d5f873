"""Hypothesis verification (sixdpose.registration.hypotheses): texture decides a flip, occlusion is not
penalised, a model without colours falls back to geometry."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from sixdpose.geometry import X_from
from sixdpose.registration import hypotheses as H
from sixdpose.registration.presets import get_preset

SIZE = np.array([0.10, 0.06, 0.04])  # box edges (m)
K = np.array([[600.0, 0, 160], [0, 600.0, 120], [0, 0, 1]])
SHAPE = (240, 320)


def box_samples(step: float):
    """Points and outward normals on the surface of a box centred at the origin (object frame)."""
    pts, nrm = [], []
    half = SIZE / 2
    for ax in range(3):
        o = [i for i in range(3) if i != ax]
        a = np.arange(-half[o[0]], half[o[0]] + 1e-9, step)
        b = np.arange(-half[o[1]], half[o[1]] + 1e-9, step)
        A, B = np.meshgrid(a, b, indexing="ij")
        for sgn in (-1, 1):
            p = np.zeros((A.size, 3))
            p[:, o[0]], p[:, o[1]], p[:, ax] = A.ravel(), B.ravel(), sgn * half[ax]
            n = np.zeros_like(p)
            n[:, ax] = sgn
            pts.append(p)
            nrm.append(n)
    return np.concatenate(pts), np.concatenate(nrm)


def colours_of(p: np.ndarray) -> np.ndarray:
    """A texture that tells +x from -x: red on one end, blue on the other, stripes across y."""
    s = (p[:, 0] - p[:, 0].min()) / np.ptp(p[:, 0])
    stripe = (np.floor(p[:, 1] / 0.015) % 2) * 0.3
    return np.clip(np.stack([s, 0.2 + stripe, 1 - s], axis=1), 0, 1)


def X(R=None, t=(0, 0, 0.5)):
    """A pose ``X_CO`` (the identity rotation by default, half a metre in front of the camera)."""
    return X_from(np.eye(3) if R is None else R, t)


def rot(axis: int, deg: float) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    v = np.zeros(3)
    v[axis] = np.radians(deg)
    return Rotation.from_rotvec(v).as_matrix()


def splat(p: np.ndarray, n: np.ndarray, c: np.ndarray, X_CO) -> tuple[np.ndarray, np.ndarray]:
    """Depth (m) and RGB in [0, 1] of the samples ``p`` (normals ``n``, colours ``c``; object frame) at
    ``X_CO``, splatted into a z-buffer in front of a grey wall 2 m away."""
    P = p @ X_CO[:3, :3].T + X_CO[:3, 3]
    front = np.einsum("ij,ij->i", n @ X_CO[:3, :3].T, P) < 0
    P, c = P[front], c[front]
    u = np.round(K[0, 0] * P[:, 0] / P[:, 2] + K[0, 2]).astype(int)
    v = np.round(K[1, 1] * P[:, 1] / P[:, 2] + K[1, 2]).astype(int)
    depth = np.full(SHAPE, 2.0)  # a wall behind
    rgb = np.full(SHAPE + (3,), 0.5)
    order = np.argsort(-P[:, 2])  # far first: the nearest written last
    depth[v[order], u[order]] = P[order, 2]
    rgb[v[order], u[order]] = c[order]
    return depth, rgb


def render(X_CO, occluder: float | None = None, lighting=(1.0, 0.0)):
    """Depth (m), RGB (uint8) and the visible mask of the box at ``X_CO`` by splatting dense samples
    into a z-buffer; ``occluder``: a plane at this depth hiding the image's left half of the object."""
    p, n = box_samples(0.0005)
    depth, rgb = splat(p, n, colours_of(p), X_CO)
    mask = depth < 1.9
    if occluder is not None:
        cols = np.flatnonzero(mask.any(axis=0))
        mid = (cols.min() + cols.max()) // 2
        depth[:, :mid] = occluder
        rgb[:, :mid] = 0.3
        mask[:, :mid] = False
    gain, offset = lighting
    rgb = np.clip(rgb * gain + offset, 0, 1)
    return H.Frame(depth, K, mask, (rgb * 255).astype(np.uint8))


def surface(coloured: bool = True) -> H.Surface:
    p, n = box_samples(0.003)
    dense, _ = box_samples(0.001)
    diameter = float(np.linalg.norm(SIZE))
    return H.build_surface(p, n, 0.003, diameter, dense if coloured else None,
                           colours_of(dense) if coloured else None)


CFG = get_preset("default", verify=True)
# a pose seen from an oblique view: three faces visible
R_TRUE = rot(0, 35) @ rot(1, -30)


def test_flipped_hypothesis_scores_lower_with_texture():
    X_true = X(R_TRUE)
    flip = X_true @ X(rot(2, 180), (0, 0, 0))  # the same box turned 180 degrees about its z axis
    frame = render(X_true, lighting=(0.7, 0.1))  # another camera's gain and offset
    sc = H.score_hypotheses(np.stack([X_true, flip]), surface(), frame, CFG)
    assert sc.textured
    # geometry cannot tell the two apart (the box is symmetric), texture does
    assert abs(sc.depth[0] - sc.depth[1]) < 0.05 and abs(sc.iou[0] - sc.iou[1]) < 0.05
    assert sc.texture[0] > 0.8 and sc.texture[1] < 0.3
    assert sc.score[0] > sc.score[1] + 0.1
    # the verification keeps the true pose when started from the flipped one
    v = H.verify_hypotheses(flip, surface(), frame, CFG, obj_id=1)
    # (the turns are about the samples' centroid, within a millimetre of the box centre)
    assert np.allclose(v.X_CO[:3, :3], R_TRUE, atol=1e-3) and np.allclose(v.X_CO[:3, 3], X_true[:3, 3], atol=2e-3)
    assert v.index != 0 and v.n_hypotheses == 1 + 3 * (CFG.verify_turns - 1)


def test_half_occluded_model_is_not_penalised():
    X_true = X(R_TRUE)
    free = H.score_hypotheses(X_true[None], surface(), render(X_true), CFG)
    hidden = H.score_hypotheses(X_true[None], surface(), render(X_true, occluder=0.3), CFG)
    # the hidden half lies behind nearer depth: occluded, not wrong; the silhouette keeps the visible half
    assert hidden.depth[0] > 0.95 and hidden.iou[0] > 0.75
    assert hidden.score[0] > free.score[0] - 0.1
    # a pose pushed 3 cm in front of the surface (into free space) is wrong, occluder or not
    near = X(R_TRUE, (0, 0, 0.47))
    assert H.score_hypotheses(near[None], surface(), render(X_true, occluder=0.3), CFG).depth[0] < 0.5


def test_textureless_model_falls_back_to_geometry(caplog):
    X_true = X(R_TRUE)
    frame = render(X_true)
    shifted = X(R_TRUE, (0.02, 0, 0.5))
    H._TEXTURELESS_LOGGED.discard(77)
    with caplog.at_level(logging.WARNING):
        v1 = H.verify_hypotheses(shifted, surface(coloured=False), frame, CFG, extra=X_true[None], obj_id=77)
        H.verify_hypotheses(shifted, surface(coloured=False), frame, CFG, obj_id=77)
    assert sum("without colours" in r.message for r in caplog.records) == 1  # said once
    assert np.allclose(v1.X_CO, X_true) and not v1.textured
    sc = H.score_hypotheses(np.stack([X_true, shifted]), surface(coloured=False), frame, CFG)
    assert (sc.texture == 0).all() and sc.score[0] > sc.score[1]


def test_icp_runs_on_the_best_few_only():
    X_true = X(R_TRUE)
    frame = render(X_true)
    calls = []

    def icp(Xh):
        calls.append(Xh)
        return Xh

    v = H.verify_hypotheses(X_true, surface(), frame, CFG, icp=icp, obj_id=1)
    assert 1 <= len(calls) <= CFG.verify_icp and v.n_icp == len(calls)
    assert np.allclose(v.X_CO, X_true)


def test_empty_mask_is_an_error():
    frame = render(X(R_TRUE))
    frame.mask[:] = False
    with pytest.raises(ValueError, match="empty instance mask"):
        H.score_hypotheses(X(R_TRUE)[None], surface(), frame, CFG)


def test_recentred_moves_a_hypothesis_onto_the_observed_cloud():
    X_true = X(R_TRUE)
    frame = render(X_true)
    off = X(R_TRUE, (0.05, -0.03, 0.52))
    back = H.recentred(off[None], surface(), frame)[0]
    assert np.allclose(back[:3, :3], R_TRUE)
    assert np.linalg.norm(back[:3, 3] - X_true[:3, 3]) < 0.005 < np.linalg.norm(off[:3, 3] - X_true[:3, 3])


def test_register_verify_end_to_end(tmp_path):
    """``register --verify`` on a small synthetic dataset: every instance right, the verification's score in
    the CSV (not the ICP fitness), and the switch recorded in the config written beside it."""
    from sixdpose.artifacts.poses import read_results
    from sixdpose.cli import main
    from sixdpose.datasets import open_dataset
    from sixdpose.evaluation.evaluate import evaluate
    from test_reg_helpers import write_synthetic_dataset

    syn = write_synthetic_dataset(tmp_path / "d", n_images=3)
    out = tmp_path / "r.csv"
    assert main(["register", "--data", str(syn), "--method", "super4pcs", "--icp", "--verify", "--workers", "1",
                 "--no-progress", "--out", str(out)]) == 0
    ests = read_results(out)
    res = evaluate(open_dataset(syn), ests, min_px=50)
    assert res.n_gt == 4 and res.accuracy == 100.0
    assert all(0 < e.score <= 1 for e in ests)
    assert "verify: true" in out.with_name("r.config.yml").read_text()


def test_local_search_moves_toward_the_true_pose():
    import dataclasses

    from sixdpose.evaluation.metrics import rotation_error

    X_true = X(R_TRUE)
    frame = render(X_true)
    off = X_true @ X(rot(2, 20), (0, 0, 0))
    cfg = dataclasses.replace(CFG, verify_search_rounds=3)
    s0 = H.score_hypotheses(off[None], surface(), frame, cfg).score
    Xb, sb = H.local_search(off[None], s0, surface(), frame, cfg)
    assert sb[0] > s0[0]
    assert rotation_error(Xb[0, :3, :3], R_TRUE) < 10.0 < rotation_error(off[:3, :3], R_TRUE)


def test_near_symmetries_of_a_box_are_its_three_half_turns():
    # geometry alone (no colours): a box maps onto itself by the half-turns about its three axes
    sym = H.near_symmetries(surface(coloured=False))
    assert len(sym) == 3
    from scipy.spatial.transform import Rotation

    rv = Rotation.from_matrix(sym[:, :3, :3]).as_rotvec()
    assert np.allclose(np.linalg.norm(rv, axis=1), np.pi, atol=0.05)
    axes = np.abs(rv / np.linalg.norm(rv, axis=1, keepdims=True))
    assert sorted(int(np.argmax(a)) for a in axes) == [0, 1, 2] and (axes.max(axis=1) > 0.99).all()
    assert np.abs(sym[:, :3, 3]).max() < 2e-3  # about the box centre
    # cached on the surface: the same array again
    s = surface(coloured=False)
    assert H.near_symmetries(s) is H.near_symmetries(s)


def test_near_symmetries_of_a_ball_are_the_half_turns_its_texture_keeps():
    """A ball maps onto itself by every rotation; its print decides. A thin seam-like print that only the
    half-turns about a tilted frame's three axes keep (a tetrahedral pattern: the sign of x y z in that
    frame, drawn as narrow bands) must give exactly those three turns first, each within 3 degrees (refining
    half-turns from a 20-degree lattice with the colours as extra ICP coordinates missed two of them by 35-45
    degrees: the peaks of a narrow print are narrower than that lattice)."""
    from scipy.spatial.transform import Rotation

    n = 6000
    i = np.arange(n) + 0.5
    zz = 1 - 2 * i / n
    rr = np.sqrt(1 - zz * zz)
    phi = np.pi * (1 + np.sqrt(5)) * i
    u = np.stack([rr * np.cos(phi), rr * np.sin(phi), zz], axis=1)  # unit sphere, evenly spread
    R_F = Rotation.from_rotvec([0.4, -0.7, 0.3]).as_matrix()  # the pattern's frame, not the object's axes
    f = u @ R_F  # coordinates in the pattern's frame
    band = np.abs(np.abs(f[:, 0] * f[:, 1] * f[:, 2]) - 0.03) < 0.004  # narrow bands, as a ball's seams
    colours = np.where(band[:, None], [0.8, 0.1, 0.1], [0.9, 0.9, 0.85])
    colours[band & (f.prod(axis=1) > 0)] = (0.1, 0.1, 0.6)  # the sign of x y z decides the band's colour
    radius = 0.037
    surf = H.build_surface(radius * u, u, 0.002, 2 * radius, radius * u, colours)
    sym = H.near_symmetries(surf, keep=6)
    rv = Rotation.from_matrix(sym[:3, :3, :3]).as_rotvec()
    assert np.allclose(np.linalg.norm(rv, axis=1), np.pi, atol=np.radians(3))
    axes = rv / np.linalg.norm(rv, axis=1, keepdims=True)
    # each of the first three is one of the pattern frame's axes (columns of R_F), all three present
    match = np.abs(axes @ R_F)
    assert (match.max(axis=1) > np.cos(np.radians(3))).all()
    assert sorted(int(np.argmax(m)) for m in match) == [0, 1, 2]


def test_verification_with_near_symmetries_undoes_a_flip_without_principal_turns():
    import dataclasses

    X_true = X(R_TRUE)
    flip = X_true @ X(rot(2, 180), (0, 0, 0))
    frame = render(X_true)
    cfg = dataclasses.replace(CFG, verify_turns=0, verify_near_symmetries=6)
    v = H.verify_hypotheses(flip, surface(), frame, cfg, obj_id=1)
    assert v.n_hypotheses == 1 + 3
    assert np.allclose(v.X_CO[:3, :3], R_TRUE, atol=1e-2) and np.allclose(v.X_CO[:3, 3], X_true[:3, 3], atol=3e-3)
    # off (and no turns): the flipped input pose is all there is
    v0 = H.verify_hypotheses(flip, surface(), frame, dataclasses.replace(cfg, verify_near_symmetries=0), obj_id=1)
    assert v0.n_hypotheses == 1 and np.allclose(v0.X_CO, flip)


def test_grey_detail_tells_a_flip_of_black_print_on_white_apart(monkeypatch):
    import dataclasses

    def print_on_white(p: np.ndarray) -> np.ndarray:
        # black stripes printed on the +x half of a white box (edges off the sample grid)
        ink = (p[:, 0] > 0) & ((np.floor((p[:, 1] + 0.0031) / 0.0125) % 2) == 0)
        return np.repeat(np.where(ink, 0.1, 0.9)[:, None], 3, axis=1)

    monkeypatch.setitem(globals(), "colours_of", print_on_white)
    X_true = X(R_TRUE)
    flip = X_true @ X(rot(2, 180), (0, 0, 0))
    frame = render(X_true, lighting=(0.8, 0.05))
    surf = surface()
    cfg = dataclasses.replace(CFG, verify_detail_share=1.0)  # the texture term is the grey detail alone
    det = H.score_hypotheses(np.stack([X_true, flip]), surf, frame, cfg)
    assert det.texture[0] > 0.4 and det.texture[1] < 0.1
    # where the model has no colours there is no detail either: geometry alone, as before
    bare = H.score_hypotheses(np.stack([X_true, flip]), surface(coloured=False), frame, cfg)
    assert not bare.textured and (bare.texture == 0).all()


def test_hemisphere_axes_cover_the_upper_hemisphere_evenly():
    """sixdpose.geometry.hemisphere_axes (the half-turn search's axes, the normals' directions of the dense
    head's symmetry search): n unit axes with z > 0, none far from its nearest neighbour's spacing, and every
    direction of the sphere within a few degrees of one of them or its opposite."""
    from sixdpose.geometry import hemisphere_axes

    A = hemisphere_axes(400)
    assert A.shape == (400, 3) and np.allclose(np.linalg.norm(A, axis=1), 1) and (A[:, 2] > 0).all()
    cos = A @ A.T
    np.fill_diagonal(cos, -1)
    nearest = np.degrees(np.arccos(np.clip(cos.max(axis=1), -1, 1)))
    assert nearest.max() < 2 * np.median(nearest)  # no cluster, no hole
    d = np.random.default_rng(0).standard_normal((2000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    worst = np.degrees(np.arccos(np.clip(np.abs(d @ A.T).max(axis=1), -1, 1))).max()
    assert worst < 10.0


def test_neighbourhood_means_equal_the_per_point_means():
    """sixdpose.geometry.neighbourhood_means (the colour search's and the surface's smoothing) equals the
    per-point mean over cKDTree neighbourhoods, for vectors and scalars; an empty neighbourhood is refused."""
    from scipy.spatial import cKDTree

    from sixdpose.geometry import neighbourhood_means

    rng = np.random.default_rng(3)
    P, ch, g = rng.random((800, 3)), rng.random((800, 3)), rng.random(800)
    nb = cKDTree(P).query_ball_point(P[:200], 0.15)
    np.testing.assert_allclose(neighbourhood_means(ch, nb), np.array([ch[i].mean(axis=0) for i in nb]), atol=1e-12)
    nb = cKDTree(P).query_ball_point(P, 0.05)
    np.testing.assert_allclose(neighbourhood_means(g, nb), np.array([g[i].mean() for i in nb]), atol=1e-12)
    assert neighbourhood_means(g, []).shape == (0,)
    with pytest.raises(ValueError, match="empty neighbourhood"):
        neighbourhood_means(g, [[0, 1], []])


def test_samples_are_read_at_the_pixel_whose_centre_is_nearest():
    """Pixel (u, v) has its centre at integer coordinates (the readers' convention): a sample projecting to
    u = 10.7 belongs to pixel 11. Stripes one pixel wide, seen head-on, correlate only when every sample
    reads its nearest pixel (truncating the projection, as the kernel once did, shifts the reading by half
    a pixel, so about half the samples read the neighbouring stripe: the true pose scored no better than a
    shifted one on a baseball's seams)."""
    z = 0.5
    px = z / K[0, 0]  # one pixel at the plane (m)
    a = np.arange(-40, 40) * px / 4 + px / 8  # four samples a pixel, none on a pixel border
    A, B = np.meshgrid(a, a, indexing="ij")
    p = np.stack([A.ravel(), B.ravel(), np.zeros(A.size)], axis=1)
    n = np.tile([0.0, 0.0, -1.0], (len(p), 1))  # facing the camera
    col_of = np.round(K[0, 0] * p[:, 0] / z + K[0, 2]).astype(int)  # the nearest pixel's column
    red = (col_of % 2 == 0)[:, None]
    colours = np.where(red, [0.8, 0.2, 0.2], [0.2, 0.8, 0.2])
    surf = H.build_surface(p, n, px / 4, float(np.ptp(a) * np.sqrt(2)), p, colours, detail_rel=0.0)
    depth = np.full(SHAPE, 2.0)
    mask = np.zeros(SHAPE, bool)
    cols = np.unique(col_of)
    rows = np.unique(np.round(K[1, 1] * p[:, 1] / z + K[1, 2]).astype(int))
    mask[rows.min():rows.max() + 1, cols.min():cols.max() + 1] = True
    depth[mask] = z
    rgb = np.zeros(SHAPE + (3,), np.uint8)
    rgb[:, 0::2] = (204, 51, 51)
    rgb[:, 1::2] = (51, 204, 51)
    sc = H.score_hypotheses(X(t=(0, 0, z))[None], surf, H.Frame(depth, K, mask, rgb), CFG)
    assert sc.texture[0] > 0.95


def test_the_val_chosen_verify_settings_read_back_as_the_command_line_gives_them():
    """One spelling of the settings chosen on val: ``as_set_args`` gives ``--set`` items that ``parse_overrides``
    reads back to the same values, which the registration config accepts."""
    import dataclasses

    from sixdpose.config import parse_overrides
    from sixdpose.registration.presets import PRESETS, VAL_CHOSEN_VERIFY, as_set_args

    fields = {**VAL_CHOSEN_VERIFY, "verify_recentre": True}
    args = as_set_args(fields)
    assert args[::2] == ["--set"] * len(fields) and "verify_recentre=true" in args
    assert parse_overrides(args[1::2]) == fields
    cfg = dataclasses.replace(PRESETS["default"], **fields)
    cfg.validate()
    assert cfg.verify_near_symmetries == 6 and cfg.verify_recentre is True


def test_slides_along_the_longest_axis_place_a_half_hidden_box_by_its_silhouette():
    import dataclasses

    surf = surface(coloured=False)
    S = H.slides(surf, 2, 0.1)
    # four translations along the box's 10 cm axis (x): +-1 and +-2 cm
    assert S.shape == (4, 4, 4) and np.allclose(S[:, :3, :3], np.eye(3))
    assert np.allclose(np.sort(np.abs(S[:, 0, 3])), [0.01, 0.01, 0.02, 0.02], atol=5e-4)
    assert np.allclose(S[:, 1:3, 3], 0, atol=1e-5)
    # the box is 10/6 = 1.67 times as long along x as along y: elongated for 1.5, not for 2
    assert len(H.slides(surf, 2, 0.1, min_elong=1.5)) == 4 and len(H.slides(surf, 2, 0.1, min_elong=2.0)) == 0
    X_true = X(R_TRUE)
    frame = render(X_true, occluder=0.3)  # the image's left half of the box hidden
    off = X_true @ X(None, (-0.02, 0, 0))  # slid 2 cm along its long axis
    cfg = dataclasses.replace(CFG, verify_turns=0, verify_slides=2, verify_slide_rel=0.1)
    v = H.verify_hypotheses(off, surf, frame, cfg, obj_id=1)
    assert v.n_hypotheses == 1 + 4 and v.index != 0
    assert np.allclose(v.X_CO, X_true, atol=1e-3)
    # off: the slid input pose is all there is
    v0 = H.verify_hypotheses(off, surf, frame, dataclasses.replace(cfg, verify_slides=0), obj_id=1)
    assert v0.n_hypotheses == 1 and np.allclose(v0.X_CO, off)


BALL_R = 0.04  # radius of the textured ball (m)


def ball_samples(step: float):
    """Points and outward normals on a ball of radius BALL_R about the origin (a Fibonacci lattice)."""
    n = int(4 * np.pi * BALL_R**2 / step**2)
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    phi = np.pi * (1 + 5**0.5) * i
    nrm = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return BALL_R * nrm, nrm


def ball_colours(p: np.ndarray) -> np.ndarray:
    """A white ball with a red seam (a wavy band, as a baseball's: the same after a half turn about z) and a
    dark logo on the side the camera sees, which tells the two apart."""
    u = p / BALL_R
    seam = np.abs(u[:, 2] - 0.5 * np.sin(2 * np.arctan2(u[:, 1], u[:, 0]))) < 0.08
    logo = (u[:, 0] > 0.4) & (np.abs(u[:, 1]) < 0.3) & (u[:, 2] < 0)
    col = np.ones((len(p), 3)) * 0.9
    col[seam] = [0.8, 0.1, 0.1]
    col[logo] = [0.1, 0.1, 0.3]
    return col


def render_ball(X_CO) -> H.Frame:
    """The ball at ``X_CO`` splatted into a z-buffer (depth in m, RGB, mask) in front of a grey wall."""
    p, n = ball_samples(0.0004)
    depth, rgb = splat(p, n, ball_colours(p), X_CO)
    return H.Frame(depth, K, depth < 1.9, (rgb * 255).astype(np.uint8))


def test_texture_search_turns_a_ball_its_geometry_cannot():
    import dataclasses

    from scipy.spatial.transform import Rotation

    p, n = ball_samples(0.003)
    dense, _ = ball_samples(0.001)
    ball = H.build_surface(p, n, 0.003, 2 * BALL_R, dense, ball_colours(dense))
    # the ball's geometry leaves its turn open, the box's does not
    assert H.rotation_free(ball) and not H.rotation_free(surface())
    R_true = Rotation.from_rotvec([0.4, -0.3, 0.2]).as_matrix()
    X_true = X(R_true)
    frame = render_ball(X_true)
    R_off = Rotation.from_rotvec([0.0, 2.0, 1.0]).as_matrix()  # 128 degrees off, about the centre
    off = X(R_true @ R_off)
    cfg = dataclasses.replace(CFG, verify_texture_lattice=1000)

    def angle(Xa):
        return np.degrees(Rotation.from_matrix(Xa[:3, :3].T @ R_true).magnitude())

    found = H.texture_search(off, ball, frame, cfg)
    assert found.shape == (cfg.verify_texture_keep, 4, 4)
    assert angle(found[0]) < 6 and np.allclose(found[0][:3, 3], X_true[:3, 3], atol=1e-3)
    v = H.verify_hypotheses(off, ball, frame, cfg, obj_id=1)
    assert v.index != 0 and angle(v.X_CO) < 6
    # off (the default): the verification cannot turn the ball back
    v0 = H.verify_hypotheses(off, ball, frame, CFG, obj_id=1)
    assert angle(v0.X_CO) > 60
