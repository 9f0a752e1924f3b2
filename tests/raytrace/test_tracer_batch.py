"""The batch-synchronous kernel: bit-identical results for any lanes, chunks and sub-steps, its samplers
against the straightforward versions, one kernel for specular fractions, and the CLI's compilation cache."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import ROOT, TRACE_SIZES
from jax.extend.random import threefry_2x32
from test_kernel import TABLE2, scene

from bsdfkit.cli.main import compile_cache, compile_cache_dir, compile_cache_wanted
from bsdfkit.core.errors import ValidationError
from bsdfkit.core.jaxconfig import x64
from bsdfkit.raytrace import PhosphorPlate, kernel, sampling, scene_effects, trace
from bsdfkit.raytrace.effects import kernel_params
from bsdfkit.raytrace.tracer import emission_width


def full(result) -> dict:
    """Every number of a result that must not depend on lanes or chunking."""
    d = result.to_dict()
    for k in ("elapsed_s", "rays_per_s", "interactions_per_s", "compile_s", "chunk"):
        d.pop(k)
    for name in ("irradiance", "incidence_histogram", "budget"):
        value = getattr(result, name)
        d[name] = None if value is None else value.tolist()
    return d


def plate_scene(tmp_path, spec=0.0, extra="[tallies]\ninteraction_budget = true"):
    if not (tmp_path / "p.json").exists():
        PhosphorPlate.constant(TABLE2).save(tmp_path / "p.json")
    return scene(f'kind = "phosphor"\nplate = "{tmp_path / "p.json"}"', rho=0.95, spec=spec, extra=extra)


def test_threefry_is_bit_identical_to_jax():
    key = jnp.asarray([0x12345678, 0x9ABCDEF0], jnp.uint32)
    ray = jnp.arange(4096, dtype=jnp.uint32) * jnp.uint32(2654435761)
    counter = jnp.arange(4096, dtype=jnp.uint32) * jnp.uint32(4) + jnp.uint32(2)
    ref = threefry_2x32((key[0], key[1]), jnp.concatenate([ray, counter]))
    a, b = sampling.threefry2x32(key, ray, counter)
    assert bool(jnp.all(a == ref[:4096])) and bool(jnp.all(b == ref[4096:]))


def test_materialise_is_the_identity():
    key = jnp.asarray([7, 9], jnp.uint32)
    xs = [jnp.arange(5, dtype=jnp.int32) - 2, jnp.asarray([-0.0, 1.5, np.inf], jnp.float32),
          jnp.asarray([True, False]), jnp.arange(3, dtype=jnp.uint32)]
    out = jax.jit(sampling.materialise)(key, xs)
    for a, b in zip(xs, out):
        assert a.dtype == b.dtype and np.array_equal(np.asarray(a), np.asarray(b))
    assert np.signbit(np.asarray(out[1])[0])  # bit patterns are kept (−0.0 stays −0.0)


@pytest.mark.slow
def test_lanes_and_chunks_do_not_change_a_single_bit(tmp_path):
    s = plate_scene(tmp_path, spec=0.2)
    ref = full(trace(s, 12_000, seed=11, chunk=12_000, lanes=16384))
    # each (lanes, emission width) is a compilation (the cost of this test); chunks of 5000 (256 lanes, one loop
    # level), 12 000 (64 lanes) at their default widths, 7001 (a short last chunk) in the reference's kernel
    for chunk, lanes in ((5_000, 256), (12_000, 64)):
        assert full(trace(s, 12_000, seed=11, chunk=chunk, lanes=lanes)) == ref, (chunk, lanes)
    assert full(trace(s, 12_000, seed=11, chunk=7_001, lanes=16384, width=16384)) == ref
    # chunks of 3000 in 1024 lanes, in a wider kernel than the chunk needs (unused emissions per call)
    assert full(trace(s, 12_000, seed=11, chunk=3_000, lanes=1024, width=16384)) == ref
    assert ref["ledger_error"] <= 1e-9


@pytest.mark.slow
def test_substeps_and_tail_levels_do_not_change_the_sums(tmp_path, monkeypatch):
    s = plate_scene(tmp_path)
    eff = scene_effects(s)
    with x64():
        params = jax.tree_util.tree_map(jnp.asarray, kernel_params(s, eff))
        key = jax.random.key_data(jax.random.key(3)).astype(jnp.uint32)
        outs = {3000: [], 700: []}
        # a compilation per (substeps, lanes) is the cost, a call is not: each kernel traces 3000 rays (more than
        # its lanes: refills, then the tail levels 1024/64 or the single level 64) and 700 (1024 lanes hold them
        # all from the first refill); substeps 1 (no inner loop), 2 and 3
        for substeps, lanes in ((1, 1024), (2, 1024), (3, 64)):
            for n in outs:
                out = kernel.trace_chunk_jit(params, key, np.uint32(100), np.int32(n), effects=eff, lanes=lanes,
                                             chunk=4096, substeps=substeps)
                outs[n].append({k: np.asarray(v).tolist() for k, v in out.items() if k != "iterations"})
    assert all(o == runs[0] for runs in outs.values() for o in runs[1:])
    assert outs[3000][0] != outs[700][0]


def _lobe_reference(key_words, ray, event, pending, b0x, b0y, sigma, dtype, max_attempts=1024):
    """The plain rejection loop over every lane (the definition the compacted sampler must reproduce)."""
    ray_lobe = ray + jnp.uint32(sampling.LOBE_STREAM)
    base = event.astype(jnp.uint32) * jnp.uint32(1024)

    def body(state):
        attempt, todo, bx, by = state
        w1, w2 = sampling.random_words(key_words, ray_lobe, [base + attempt.astype(jnp.uint32)])
        u1, u2 = sampling.to_unit(w1, dtype), sampling.to_unit(w2, dtype)
        r = jnp.sqrt(-2.0 * jnp.log1p(-u1))
        c, s = sampling.cos_sin_turn(u2)
        gx = b0x + sigma * r * c
        gy = b0y + sigma * r * s
        ok = gx * gx + gy * gy < 1.0
        take = todo & ok
        return attempt + 1, todo & ~ok, jnp.where(take, gx, bx), jnp.where(take, gy, by)

    zero = jnp.zeros_like(b0x)
    _, todo, bx, by = jax.lax.while_loop(lambda s: jnp.any(s[1]) & (s[0] < max_attempts), body,
                                         (jnp.int32(0), pending, zero, zero))
    return bx, by, pending & ~todo


def test_compacted_lobe_sampler_equals_plain_rejection():
    n = 4096
    rng = np.random.default_rng(5)
    theta = np.arcsin(np.sqrt(rng.random(n)))
    phi = rng.random(n) * 2 * np.pi
    b0x = jnp.asarray(np.sin(theta) * np.cos(phi) * 0.999, jnp.float32)
    b0y = jnp.asarray(np.sin(theta) * np.sin(phi) * 0.999, jnp.float32)
    sigma = jnp.asarray(rng.choice([0.05, 0.3, 1.5], n), jnp.float32)
    ray = jnp.arange(n, dtype=jnp.uint32) * jnp.uint32(3)
    event = jnp.asarray(rng.integers(1, 50, n), jnp.int32)
    key = jnp.asarray([11, 12], jnp.uint32)
    for share in (0.02, 0.3, 1.0):  # few pending (compacted at once) … all pending (full-width retries first)
        pending = jnp.asarray(rng.random(n) < share)
        got = jax.jit(sampling.lobe_beta, static_argnums=(7,))(key, ray, event, pending, b0x, b0y, sigma,
                                                                jnp.float32)
        ref = jax.jit(_lobe_reference, static_argnums=(7,))(key, ray, event, pending, b0x, b0y, sigma, jnp.float32)
        for a, b in zip(got, ref):
            assert np.array_equal(np.asarray(a), np.asarray(b)), share


@pytest.mark.slow
def test_specular_fraction_is_a_number_for_plate_scenes(tmp_path):
    diffuse, mirror = plate_scene(tmp_path, spec=0.0), plate_scene(tmp_path, spec=0.5)
    assert scene_effects(diffuse) == scene_effects(mirror)  # one compiled kernel for both
    sizes = dict(chunk=8_000, **TRACE_SIZES)
    a = trace(diffuse, 8_000, seed=4, **sizes)
    b = trace(diffuse, 8_000, seed=4, effects=replace(scene_effects(diffuse), specular=False), **sizes)
    assert full(a) == full(b)  # the mirror branch with fraction 0 changes nothing
    assert trace(mirror, 8_000, seed=4, **sizes).LER != a.LER


def test_emission_width_buckets():
    assert [emission_width(n) for n in (1, 1024, 1025, 400_000, 2 ** 20)] == [1024, 1024, 2048, 2 ** 19, 2 ** 20]


@pytest.mark.parametrize("width", [1000, 2048, 3 * 4096, 2 ** 23, True])
def test_emission_width_must_be_a_power_of_two_holding_the_chunk(tmp_path, width):
    # chunk 4096 here: 2048 is too narrow, 1000 and 12288 no powers of two, 2**23 beyond MAX_CHUNK
    with pytest.raises(ValidationError, match="emission width"):
        trace(plate_scene(tmp_path), 8_192, seed=1, chunk=4096, width=width)


# --- the command line's persistent compilation cache -------------------------------------------------------------

def _cli(args, env_extra, cwd):
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_") and k != "BSDFKIT_NO_COMPILE_CACHE"}
    env.update(env_extra)
    return subprocess.Popen([sys.executable, "-m", "bsdfkit", *args], cwd=cwd, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _numbers(stdout: str) -> dict:
    d = json.loads(stdout)
    return {k: d[k] for k in ("LER", "extracted", "absorbed", "ledger_error", "interactions")}


@pytest.mark.slow
def test_compile_cache_is_on_by_default_shared_by_concurrent_processes_and_can_be_switched_off(tmp_path):
    """Four cold commands at once (one start-up and compilation each, the expensive part): two by default into
    one empty cache (concurrent writers), one with --no-compile-cache, one with BSDFKIT_NO_COMPILE_CACHE=1; then
    a reader of what the two wrote. Every run gives the same numbers, only the default ones write a cache.
    Two writers are all a race needs (and all that run at once on two cores); 64 lanes compile in about half
    the CPU time of the default (the emission width, 2048 here); the cache and program code are the same."""
    args = ["trace", str(ROOT / "fitting" / "scenes" / "example.toml"), "--rays", "3000", "--lanes", "64", "--json"]
    env = {"XDG_CACHE_HOME": str(tmp_path / "x")}
    runs = {
        "flag": ({"XDG_CACHE_HOME": str(tmp_path / "b")}, ["--no-compile-cache"]),
        "env": ({"XDG_CACHE_HOME": str(tmp_path / "c"), "BSDFKIT_NO_COMPILE_CACHE": "1"}, []),
    }
    procs = [_cli(args, env, tmp_path) for _ in range(2)]  # both start with an empty cache: concurrent writers
    off = {name: _cli(args + extra, e, tmp_path) for name, (e, extra) in runs.items()}
    outs = [p.communicate(timeout=600) for p in procs]
    outs_off = {name: p.communicate(timeout=600) for name, p in off.items()}
    assert all(p.returncode == 0 for p in procs), [o[1][-2000:] for o in outs]
    assert all(p.returncode == 0 for p in off.values()), {k: v[1][-2000:] for k, v in outs_off.items()}
    assert not (tmp_path / "b" / "bsdfkit").exists() and not (tmp_path / "c" / "bsdfkit").exists()
    assert _numbers(outs[0][0]) == _numbers(outs_off["flag"][0]) == _numbers(outs_off["env"][0])
    entries = list((tmp_path / "x" / "bsdfkit" / "jax").glob("*-cache"))
    assert entries
    after = _cli(args, env, tmp_path)  # a reader of what the two wrote
    out, err = after.communicate(timeout=600)
    assert after.returncode == 0
    for text in [err] + [o[1] for o in outs]:
        assert "Error reading persistent compilation cache" not in text
        assert "persistent compilation cache" not in text.lower() or "error" not in text.lower()
    assert all(_numbers(o[0]) == _numbers(out) for o in outs)


def test_cli_cache_settings_are_scoped_and_not_made_on_import(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert compile_cache_dir() == tmp_path / "bsdfkit" / "jax"
    monkeypatch.setenv("BSDFKIT_NO_COMPILE_CACHE", "1")
    assert not compile_cache_wanted() and not compile_cache_wanted(True)
    monkeypatch.setenv("BSDFKIT_NO_COMPILE_CACHE", "0")
    assert compile_cache_wanted() and not compile_cache_wanted(True)
    before = dict(os.environ)
    with compile_cache(True) as where:  # JAX is imported in this process: its configuration is left alone
        assert where is None and dict(os.environ) == before
    assert dict(os.environ) == before
    code = ("import os, bsdfkit, bsdfkit.cli.main; "
            "print(any(k.startswith('JAX_') for k in os.environ), 'jax' in __import__('sys').modules)")
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_")}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert done.stdout.split() == ["False", "False"]
