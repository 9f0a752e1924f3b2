"""Counter-based random numbers and direction sampling (pure JAX functions on arrays of rays).

Random numbers. Every random word is Threefry-2x32 ([Salmon-2011]; ``jax.extend.random``) of the
key derived from the seed and the counter pair ``(ray, event·4 + h)``: ``ray`` is the global ray index
(< 2³¹), ``event`` the ray's interaction number (0 = emission), ``h`` ∈ {0, 1, 2} gives 6 words per event
(the spectral mode also draws h = 3: 8 words). Lobe-rejection attempts use ``(ray + 2³¹, event·1024 + attempt)``.
A ray's random numbers therefore depend only on (seed, ray, event), never on the chunk or lane it is traced in.

Directions (θ from the surface normal n, φ azimuth, u uniform in [0, 1)):

* Lambertian (cosine-weighted): sin θ = √u₁, cos θ = √(1 − u₁), φ = 2πu₂ (cos φ, sin φ by
  :func:`cos_sin_turn`).
* cos^m intensity: pdf(cos θ) ∝ cos^m θ ⇒ cos θ = (1 − u)^{1/(m+1)}; m = 1 is Lambertian.
* Mirror: d' = d − 2(d·n)n.
* Gaussian lobe in Harvey–Shack direction cosines: β = β0 + σ(g₁, g₂), g Box–Muller normals; samples with
  |β| ≥ 1 are rejected and redrawn, which renormalises the lobe over the unit disk.
* Tabulated BSDF linear in s = sin²θ: invert the piecewise-quadratic CDF exactly (see :func:`table_s`).

Local frames use the branchless orthonormal basis of Duff et al., "Building an orthonormal basis,
revisited", JCGT 6(1), 2017 ([Duff-2017]). Keys: docs/references.md.
"""
from __future__ import annotations

import jax.numpy as jnp
from jax import lax

TWO_PI = 2.0 * 3.141592653589793
# minimax polynomials P, Q of z = a² with sin a ≈ a + a³P(z), cos a ≈ 1 − a²/2 + a⁴Q(z) on |a| ≤ π/4 (Cephes
# sinf/cosf for float32, sin/cos for float64), highest power first
_SIN32 = (-1.9515295891e-4, 8.3321608736e-3, -1.6666654611e-1)
_COS32 = (2.443315711809948e-5, -1.388731625493765e-3, 4.166664568298827e-2)
_SIN64 = (1.58962301576546568060e-10, -2.50507477628578072866e-8, 2.75573136213857245213e-6,
          -1.98412698295895385996e-4, 8.33333333332211858878e-3, -1.66666666666666307295e-1)
_COS64 = (-1.13585365213876817300e-11, 2.08757008419747316778e-9, -2.75573141792967388112e-7,
          2.48015872888517045348e-5, -1.38888888888730564116e-3, 4.16666666666665929218e-2)
LOBE_STREAM = 2 ** 31
#: lobe retries run on 1/LOBE_NARROW of the lanes (see :func:`lobe_beta`)
LOBE_NARROW = 32
#: lobe attempts per ray and event (the counter of attempt a is event·LOBE_ATTEMPTS + a)
LOBE_ATTEMPTS = 1024


_ROTATIONS = ((13, 15, 26, 6), (17, 29, 16, 24))
_PARITY = 0x1BD11BDA


def _rotl(x, r: int):
    return (x << jnp.uint32(r)) | (x >> jnp.uint32(32 - r))


def threefry2x32(key_words, x0, x1):
    """Threefry-2x32 (20 rounds, [Salmon-2011]) of the counter pairs (x0, x1) under ``key_words``.

    Written out element-wise (no concatenation or reshaping of the counters), bit-identical to
    ``jax.extend.random.threefry_2x32`` applied to ``concatenate([x0, x1])`` (tested), so XLA fuses it into
    the surrounding kernel.

    Parameters
    ----------
    key_words : jax.Array
        The key's two uint32 words, shape (2,).
    x0, x1 : jax.Array
        The two uint32 counter words.

    Returns
    -------
    x0, x1 : jax.Array
        The two uint32 output words.
    """
    k0, k1 = key_words[0], key_words[1]
    ks = (k0, k1, k0 ^ k1 ^ jnp.uint32(_PARITY))
    x0 = x0 + ks[0]
    x1 = x1 + ks[1]
    for i in range(5):
        for r in _ROTATIONS[i % 2]:
            x0 = x0 + x1
            x1 = _rotl(x1, r)
            x1 = x0 ^ x1
        x0 = x0 + ks[(i + 1) % 3]
        x1 = x1 + ks[(i + 2) % 3] + jnp.uint32(i + 1)
    return x0, x1


def random_words(key_words, ray, counters):
    """Threefry words for the counter pairs (ray, c) for each c in ``counters``: 2 words per counter.

    ``key_words`` (2,) uint32, ``ray`` (n,) uint32, ``counters`` list of (n,) uint32. Returns a list of
    2·len(counters) arrays (n,) uint32, the two words of counter h at positions 2h and 2h + 1.

    Parameters
    ----------
    key_words : jax.Array
        The key's two uint32 words, shape (2,).
    ray : jax.Array
        Ray indices (n,), uint32.
    counters : list of jax.Array
        Second counter words, each (n,) uint32.

    Returns
    -------
    list of jax.Array
        The 2·len(counters) uint32 words.
    """
    words = []
    for c in counters:
        words += list(threefry2x32(key_words, ray, c))
    return words


def event_uniforms(key_words, ray, event, dtype, count: int = 6):
    """``count`` (≤ 8) uniforms in [0, 1) for (ray, event): counters event·4 + h, h = 0 … 3.

    Word i comes from counter h = i // 2, so the first words do not change when fewer are drawn (the
    spectral mode's conversion draws words 6 and 7, h = 3, which no other mode uses).

    Parameters
    ----------
    key_words : jax.Array
        The key's two uint32 words, shape (2,).
    ray : jax.Array
        Ray indices (n,), uint32.
    event : jax.Array
        Event number of each ray (0: emission).
    dtype : dtype
        float32 or float64.
    count : int
        Number of uniforms, at most 8.

    Returns
    -------
    list of jax.Array
        ``count`` arrays of uniforms in [0, 1) [-].
    """
    base = event.astype(jnp.uint32) * jnp.uint32(4)
    blocks = [base + jnp.uint32(h) for h in range((count + 1) // 2)]
    words = materialise(key_words, random_words(key_words, ray, blocks)[:count])
    return [to_unit(w, dtype) for w in words]


def materialise(key_words, arrays):
    """``arrays`` (a list) unchanged, but each computed once into memory before any use.

    XLA fuses cheap element-wise producers into each of their consumers; for the 20 Threefry rounds behind a
    uniform used in several places (or a hit point used by every branch) that means recomputing them several
    times (measured ~2-3x slower interactions on CPU). ``lax.optimization_barrier`` is removed before fusion on
    CPU, so the arrays pass through a one-trip ``while`` loop whose trip count XLA cannot see (it depends on
    the key): loop operands are always materialised. The loop body is the identity on its only trip.

    Parameters
    ----------
    key_words : jax.Array
        The key's two uint32 words, shape (2,).
        Only used to make the loop's trip count opaque to XLA.
    arrays : list of jax.Array
        The arrays to materialise.

    Returns
    -------
    list of jax.Array
        The same values.
    """
    one = ((key_words[0] | jnp.uint32(1)) > 0).astype(jnp.uint32)  # 1, but not a compile-time constant

    def ident(a, i):
        if a.dtype == jnp.bool_:
            return a ^ (i > 0)
        if jnp.issubdtype(a.dtype, jnp.floating):
            ut = jnp.uint32 if a.dtype == jnp.float32 else jnp.uint64
            return lax.bitcast_convert_type(lax.bitcast_convert_type(a, ut) ^ i.astype(ut), a.dtype)
        return a ^ i.astype(a.dtype)

    def body(state):
        i, xs = state
        return i + jnp.uint32(1), [ident(a, i) for a in xs]  # i = 0 on the only trip: identity

    _, out = lax.while_loop(lambda s: s[0] < one, body, (jnp.uint32(0), list(arrays)))
    return out


def to_unit(bits, dtype):
    """uint32 → uniform in [0, 1): top 24 bits for float32, all 32 bits for float64 (both exact).

    Parameters
    ----------
    bits : jax.Array
        Random uint32 words.
    dtype : dtype
        float32 or float64.

    Returns
    -------
    jax.Array
        Uniforms in [0, 1) [-].
    """
    if jnp.dtype(dtype) == jnp.float32:
        return (bits >> jnp.uint32(8)).astype(jnp.float32) * jnp.float32(2.0 ** -24)
    return bits.astype(jnp.float64) * (2.0 ** -32)


def orthonormal_basis(nx, ny, nz):
    """Tangents t1, t2 with (t1, t2, n) right-handed and orthonormal (Duff et al. 2017, Listing 3).

    Parameters
    ----------
    nx, ny, nz : jax.Array
        Unit normal n [-].

    Returns
    -------
    t1, t2 : tuple of jax.Array
        The two unit tangents, each as (x, y, z) [-].
    """
    sign = jnp.where(nz >= 0, 1.0, -1.0).astype(nx.dtype)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    t1 = (1.0 + sign * nx * nx * a, sign * b, -sign * nx)
    t2 = (b, sign + ny * ny * a, -ny)
    return t1, t2


def cos_sin_turn(u):
    """(cos 2πu, sin 2πu) for u in [0, 1) (the azimuth of a uniform u), in the dtype of ``u``.

    XLA:CPU evaluates ``jnp.cos``/``jnp.sin`` by a scalar libm call per element, which also keeps the fusion
    around it from vectorising (measured: 27 % of the minimal kernel's time was in ``cosf``/``sinf``). Here the
    reduction is exact (4u − round(4u) is exact in binary floating point, so a = 2πu − qπ/2 has one rounding,
    |a| ≤ π/4) and sin a, cos a are Cephes' minimax polynomials, followed by a quarter-turn rotation. Max error
    1.1e−7 in float32 (libm on a float32 2πu: 4e−7) and 3.5e−16 in float64, over all 2²⁴ uniforms of the float32
    kernel.

    Parameters
    ----------
    u : jax.Array
        Fractions of a turn in [0, 1) [-].

    Returns
    -------
    cos, sin : jax.Array
        cos 2πu and sin 2πu [-].
    """
    dt = u.dtype
    f = 4.0 * u
    q = jnp.round(f)  # quarter turns 0 … 4
    a = (f - q) * jnp.asarray(TWO_PI / 4.0, dt)
    z = a * a
    ps, pc = (_SIN32, _COS32) if dt == jnp.float32 else (_SIN64, _COS64)
    s_poly, c_poly = ps[0], pc[0]
    for k in ps[1:]:
        s_poly = s_poly * z + k
    for k in pc[1:]:
        c_poly = c_poly * z + k
    s = (a + a * z * s_poly).astype(dt)
    c = (1.0 - 0.5 * z + z * z * c_poly).astype(dt)
    cos = jnp.where(q == 1, -s, jnp.where(q == 2, -c, jnp.where(q == 3, s, c)))
    sin = jnp.where(q == 1, c, jnp.where(q == 2, -s, jnp.where(q == 3, -c, s)))
    return cos, sin


def local_to_world_cs(sin_t, cos_t, c, s, nx, ny, nz):
    """Direction with polar angle θ (from n; its sine and cosine) and azimuth φ (cos φ = c, sin φ = s) in the
    frame of n.

    Parameters
    ----------
    sin_t, cos_t : jax.Array
        Sine and cosine of the polar angle from n [-].
    c, s : jax.Array
        Cosine and sine of the azimuth [-].
    nx, ny, nz : jax.Array
        Unit normal n [-].

    Returns
    -------
    tuple of jax.Array
        The unit direction (x, y, z) [-].
    """
    (ax, ay, az), (bx, by, bz) = orthonormal_basis(nx, ny, nz)
    lx, ly = sin_t * c, sin_t * s
    return (lx * ax + ly * bx + cos_t * nx, lx * ay + ly * by + cos_t * ny, lx * az + ly * bz + cos_t * nz)


def lambertian_angles(u1, u2):
    """(sin θ, cos θ, cos φ, sin φ) of a cosine-weighted direction.

    Parameters
    ----------
    u1, u2 : jax.Array
        Uniforms in [0, 1) for the polar angle and the azimuth [-].

    Returns
    -------
    tuple of jax.Array
        sin θ, cos θ, cos φ, sin φ [-].
    """
    return (jnp.sqrt(u1), jnp.sqrt(1.0 - u1)) + cos_sin_turn(u2)


def cos_power_angles(u1, u2, m):
    """(sin θ, cos θ, cos φ, sin φ) for intensity ∝ cos^m θ: cos θ = (1 − u₁)^{1/(m+1)}.

    Parameters
    ----------
    u1, u2 : jax.Array
        Uniforms in [0, 1) for the polar angle and the azimuth [-].
    m : float or jax.Array
        Exponent of the cos^m θ intensity [-] (1: Lambertian).

    Returns
    -------
    tuple of jax.Array
        sin θ, cos θ, cos φ, sin φ [-].
    """
    cos_t = (1.0 - u1) ** (1.0 / (m + 1.0))
    cos_t = cos_t.astype(u1.dtype)
    return (jnp.sqrt(jnp.maximum(1.0 - cos_t * cos_t, 0.0)), cos_t) + cos_sin_turn(u2)


def mirror(dx, dy, dz, nx, ny, nz):
    """Specular reflection d − 2(d·n)n.

    Parameters
    ----------
    dx, dy, dz : jax.Array
        Unit incident direction d [-].
    nx, ny, nz : jax.Array
        Unit normal n [-].

    Returns
    -------
    tuple of jax.Array
        The reflected direction (x, y, z) [-].
    """
    k = 2.0 * (dx * nx + dy * ny + dz * nz)
    return dx - k * nx, dy - k * ny, dz - k * nz


def lobe_beta(key_words, ray, event, pending, beta0x, beta0y, sigma, dtype):
    """Harvey–Shack lobe sample β ~ N(β0, σ²I) conditioned on |β| < 1, by rejection.

    Lanes with ``pending`` false are untouched. Attempt ``a`` of a ray uses the counter pair
    (ray + 2³¹, event·1024 + a). Returns (βx, βy, accepted); a lane not accepted after :data:`LOBE_ATTEMPTS`
    (probability < (1 − p_acc)^1024, p_acc ≳ 0.1 for σ ≤ 2) reports accepted = False and the caller
    falls back to a Lambertian direction.

    Attempt 0 runs on every lane; the few rays it rejects (lobes reaching past the unit disk) are compacted
    into 1/:data:`LOBE_NARROW` of the lanes for the remaining attempts, so the retries do not cost a pass over
    every lane each (full-width retries only while more rays are pending than fit). A ray's attempts and
    their random numbers are the same either way.

    Parameters
    ----------
    key_words : jax.Array
        The key's two uint32 words, shape (2,).
    ray : jax.Array
        Ray indices (n,), uint32.
    event : jax.Array
        Event number of each ray.
    pending : jax.Array
        Boolean, lanes that need a sample.
    beta0x, beta0y : jax.Array
        Lobe centre β0 in direction cosines [-].
    sigma : jax.Array
        Lobe width in direction-cosine units [-].
    dtype : dtype
        float32 or float64.

    Returns
    -------
    bx, by : jax.Array
        The sampled β [-] (0 where not accepted).
    accepted : jax.Array
        Boolean.
    """
    n = ray.shape[0]
    ray_lobe = ray + jnp.uint32(LOBE_STREAM)
    base = event.astype(jnp.uint32) * jnp.uint32(LOBE_ATTEMPTS)
    zero = jnp.zeros_like(beta0x)

    def attempt(a, rl, bs, b0x, b0y, sg):
        w1, w2 = materialise(key_words, random_words(key_words, rl, [bs + a]))
        u1, u2 = to_unit(w1, dtype), to_unit(w2, dtype)
        r = jnp.sqrt(-2.0 * jnp.log1p(-u1))
        c, s = cos_sin_turn(u2)
        gx = b0x + sg * r * c
        gy = b0y + sg * r * s
        return gx, gy, gx * gx + gy * gy < 1.0

    def body_full(state):
        a, todo, bx, by = state
        gx, gy, ok = attempt(a, ray_lobe, base, beta0x, beta0y, sigma)
        take = todo & ok
        return a + jnp.uint32(1), todo & ~ok, jnp.where(take, gx, bx), jnp.where(take, gy, by)

    a, todo, bx, by = body_full((jnp.uint32(0), pending, zero, zero))
    narrow = max(n // LOBE_NARROW, 1)

    def cond_full(state):
        return (jnp.sum(state[1], dtype=jnp.int32) > narrow) & (state[0] < LOBE_ATTEMPTS)

    a, todo, bx, by = lax.while_loop(cond_full, body_full, (a, todo, bx, by))
    # the remaining rays, compacted
    count = jnp.sum(todo, dtype=jnp.int32)
    (idx,) = jnp.nonzero(todo, size=narrow, fill_value=0)
    valid = jnp.arange(narrow) < count
    sub = (ray_lobe[idx], base[idx], beta0x[idx], beta0y[idx], sigma[idx])

    def cond_narrow(state):
        return jnp.any(state[1]) & (state[0] < LOBE_ATTEMPTS)

    def body_narrow(state):
        a, t, sx, sy = state
        gx, gy, ok = attempt(a, *sub)
        take = t & ok
        return a + jnp.uint32(1), t & ~ok, jnp.where(take, gx, sx), jnp.where(take, gy, sy)

    _, t, sx, sy = lax.while_loop(cond_narrow, body_narrow, (a, valid, zero[:narrow], zero[:narrow]))
    dest = jnp.where(valid, idx, n)  # out of range: dropped
    bx = bx.at[dest].set(sx, mode="drop")
    by = by.at[dest].set(sy, mode="drop")
    todo = todo.at[dest].set(t, mode="drop")
    return bx, by, pending & ~todo


def table_s(u, s_nodes, f_nodes, cdf):
    """s = sin²θ sampled from a pdf linear in s between nodes (rows per lane).

    In cell k (s_k ≤ s ≤ s_{k+1}) the pdf is f_k + κ(s − s_k), κ = (f_{k+1} − f_k)/(s_{k+1} − s_k), and the CDF
    is F_k + f_k x + κx²/2 with x = s − s_k. For a target r = u − F_k the root is
    x = 2r / (f_k + √(f_k² + 2κr)) (stable for κ → 0).

    Parameters
    ----------
    u : jax.Array
        Uniforms in [0, 1) (n,) [-].
    s_nodes : jax.Array
        Nodes of s = sin²θ per lane (n, T) [-].
    f_nodes : jax.Array
        The normalised pdf of s at the nodes (n, T) [-].
    cdf : jax.Array
        The CDF at the nodes (n, T) [-].

    Returns
    -------
    jax.Array
        Sampled s in [0, 1] [-].
    """
    T = s_nodes.shape[-1]
    k = jnp.clip(jnp.sum(cdf <= u[:, None], axis=-1) - 1, 0, T - 2)
    take = lambda a, i: jnp.take_along_axis(a, i[:, None], axis=-1)[:, 0]  # noqa: E731
    s0, s1 = take(s_nodes, k), take(s_nodes, k + 1)
    f0, f1 = take(f_nodes, k), take(f_nodes, k + 1)
    r = jnp.maximum(u - take(cdf, k), 0.0)
    ds = s1 - s0
    kappa = jnp.where(ds > 0, (f1 - f0) / jnp.where(ds > 0, ds, 1.0), 0.0)
    den = f0 + jnp.sqrt(jnp.maximum(f0 * f0 + 2.0 * kappa * r, 0.0))
    x = jnp.where(den > 0, 2.0 * r / jnp.where(den > 0, den, 1.0), 0.0)
    return jnp.clip(s0 + jnp.minimum(x, ds), 0.0, 1.0)
