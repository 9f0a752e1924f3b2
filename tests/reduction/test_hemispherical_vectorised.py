"""The hemispherical engine's vectorised steps against the per-sample Python they replace (kept here as oracles)."""
from __future__ import annotations

import numpy as np
import pytest

from bsdfkit.reduction import hemispherical as hs
from bsdfkit.reduction.hemispherical import EDGE_DROP, WIDE_WINDOW


def straight_reference(x, g, s, j, step, tail_excess):
    """The former per-sample test: one numpy.polyfit per scale."""
    n = x.size
    outer = [k for k in (j + step, j + 2 * step, j + 3 * step) if 0 <= k < n]
    if not outer:
        return False, 0.0
    ok = True
    tol = 0.0
    wide = np.arange(j + step, n if step > 0 else -1, step)
    wide = wide[np.abs(x[wide] - x[j]) <= WIDE_WINDOW]
    for ks, factor in ((np.array(outer), 1.0 if len(outer) > 1 else 3.0), (wide, 3.0)):
        if ks.size < 2 and factor > 1.0 and ks is wide:
            continue
        pred = g[ks[0]] if ks.size == 1 else np.polyval(np.polyfit(x[ks], g[ks], 1), x[j])
        t = factor * tail_excess * abs(pred) + 2.0 * s[j]
        ok &= bool(abs(g[j] - pred) <= t)
        tol = max(tol, t)
    return ok, tol


def walk_reference(x, g, s, start, step, tail_excess, min_fall=0.0):
    n = x.size
    j = start
    while 0 <= j < n:
        if not 0 <= j + step < n:
            return j + step
        if g[start] - g[j] < min_fall:
            j += step
            continue
        here, tol = straight_reference(x, g, s, j, step, tail_excess)
        wide = np.arange(j + step, n if step > 0 else -1, step)
        wide = wide[np.abs(x[wide] - x[j]) <= WIDE_WINDOW]
        far = g[wide[-1]] if wide.size >= 3 else g[min(max(j + 3 * step, 0), n - 1)]
        settled = abs(g[j] - far) <= EDGE_DROP * abs(g[start] - g[j]) + tol
        if here and settled:
            nxt, _ = straight_reference(x, g, s, j + step, step, tail_excess)
            if nxt or not 0 <= j + 2 * step < n:
                return j
        j += step
    return j


def profiles(seed: int = 3):
    """Gaussian and power-law lobes on a floor, fine and coarse, uniform and non-uniform sampling, with noise."""
    rng = np.random.default_rng(seed)
    for k in range(20):
        n = int(rng.integers(4, 200))
        x = np.sort(rng.uniform(-1.0, 1.0, n)) if k % 3 == 0 else np.linspace(-0.99, 0.99, n)
        if k % 5 == 0:
            x = np.sort(np.concatenate([x, rng.uniform(0.3, 0.5, 50)]))
        c, w = rng.uniform(-0.5, 0.8), 10 ** rng.uniform(-2.5, -0.3)
        lobe = np.exp(-0.5 * ((x - c) / w) ** 2) if k % 2 else 1.0 / (1e-3 + np.abs(x - c) ** 2)
        g = 0.05 * (1.0 - 0.3 * x ** 2) + rng.uniform(0.1, 100.0) * lobe
        s = np.abs(g) * rng.uniform(0.0, 0.05) + 1e-6
        g = g + rng.normal(0.0, 1.0, x.size) * s * (k % 4 != 0)
        yield x, g, s


@pytest.mark.parametrize("tail_excess", [0.02, 0.2])
def test_straightness_equals_per_sample_fits(tail_excess):
    for x, g, s in profiles():
        for step in (-1, 1):
            st = hs._straightness(x, g, s, step, tail_excess)
            for j in range(x.size):
                ok, tol = straight_reference(x, g, s, j, step, tail_excess)
                assert st.ok[j] == ok
                # polyfit's own rounding reaches 6e-12 here (the centred closed form is within 3e-14 of the
                # line in rational arithmetic on these profiles)
                assert st.tol[j] == pytest.approx(tol, rel=1e-10, abs=0.0)


def test_walks_and_edges_equal_the_reference():
    for x, g, s in profiles(7):
        for p in {int(np.argmax(g)), x.size // 2, 0, x.size - 1}:
            for step in (-1, 1):
                for fall in (0.0, 0.5 * (g[p] - g.min())):
                    assert hs._walk(x, g, s, p, step, 0.02, fall) == walk_reference(x, g, s, p, step, 0.02, fall)


def clip_reference(poly, bound, sign):
    """The former one-polygon Sutherland–Hodgman step."""
    out = []
    n = len(poly)
    for k in range(n):
        (p, b), (q, c) = poly[k], poly[(k + 1) % n]
        dp, dq = sign * (p[0] - bound), sign * (q[0] - bound)
        if dp >= 0:
            out.append((p, b))
        if (dp >= 0) != (dq >= 0):
            t = dp / (dp - dq)
            out.append((p + t * (q - p), b + t * (c - b)))
    return out


def cells_reference(itp):
    """The former triangle-by-triangle clipping of an interpolant's triangles to one period."""
    simp = itp.tri.simplices
    pts = itp.tri.points[simp].copy()
    pts[:, :, 0] /= itp.azimuth_weight
    nodes = itp.point_node[simp]
    psi_c, r_c = pts[:, :, 0].mean(axis=1), pts[:, :, 1].mean(axis=1)
    on_rim = (nodes > itp.n_records).all(axis=1)
    outside = on_rim & (r_c > itp._top(psi_c) * (1.0 + 1e-12))
    lo, hi = pts[:, :, 0].min(axis=1), pts[:, :, 0].max(axis=1)
    inner = ~outside & (lo >= -np.pi) & (hi <= np.pi)
    eye = np.broadcast_to(np.eye(3), (int(inner.sum()), 3, 3))
    out_nodes, out_bary, out_pts = [nodes[inner]], [eye], [pts[inner]]
    for t in np.flatnonzero(~outside & ~inner & (hi > -np.pi) & (lo < np.pi)):
        poly = [(pts[t, k], np.eye(3)[k]) for k in range(3)]
        for bound, sign in ((-np.pi, 1.0), (np.pi, -1.0)):
            poly = clip_reference(poly, bound, sign)
            if len(poly) < 3:
                break
        for k in range(1, len(poly) - 1):
            tri = (poly[0], poly[k], poly[k + 1])
            out_nodes.append(nodes[t][None, :])
            out_bary.append(np.stack([v[1] for v in tri])[None])
            out_pts.append(np.stack([v[0] for v in tri])[None])
    p = np.concatenate(out_pts)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    return np.concatenate(out_nodes), np.concatenate(out_bary), area, p[:, :, 1]


def test_batched_clipping_equals_the_triangle_loop_bit_for_bit():
    from bsdfkit.reduction import disk

    rng = np.random.default_rng(11)
    cases = []
    for n, weight in ((40, disk.AZIMUTH_WEIGHT), (300, disk.AZIMUTH_WEIGHT), (300, 0.5)):
        r = np.sqrt(rng.uniform(0.0, 0.8, n))
        a = rng.uniform(-np.pi, np.pi, n)
        cases.append(disk.build(r * np.cos(a), r * np.sin(a), (0.0, 0.0), azimuth_weight=weight))
    psi, rr = np.meshgrid(np.radians(np.arange(0.0, 360.0, 15.0)), np.linspace(0.05, 0.9, 12))
    cases.append(disk.build((rr * np.cos(psi)).ravel(), (rr * np.sin(psi)).ravel(), (0.0, 0.0)))
    for itp in cases:
        new, old = itp._cells(), cells_reference(itp)
        psi_t = itp.tri.points[itp.tri.simplices][:, :, 0] / itp.azimuth_weight
        assert np.any((psi_t.min(axis=1) < -np.pi) & (psi_t.max(axis=1) > -np.pi))  # the seam is crossed
        for a, b in zip(new, old):
            np.testing.assert_array_equal(a, b)


def test_straightness_with_repeated_positions_falls_back_to_polyfit():
    x = np.array([-0.2, -0.1, -0.1, -0.1, 0.01, 0.01, 0.01, 0.05, 0.1, 0.1, 0.1, 0.3])
    g = np.array([1.0, 1.1, 1.3, 1.2, 5.0, 6.0, 5.5, 2.0, 1.2, 1.1, 1.15, 1.0])
    s = np.full(x.size, 0.01)
    with np.errstate(all="ignore"), pytest.warns(np.exceptions.RankWarning):
        for step in (-1, 1):
            st = hs._straightness(x, g, s, step, 0.02)
            for j in range(x.size):
                ok, tol = straight_reference(x, g, s, j, step, 0.02)
                assert st.ok[j] == ok and st.tol[j] == pytest.approx(tol, rel=1e-10, abs=0.0)
