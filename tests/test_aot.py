"""motorid._aot: compiled programs kept on disk give the same numbers as plain JAX."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest


SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    from motorid._aot import cached_jit

    TRACES = []

    def f(x, scale, names):
        TRACES.append(1)  # runs only while JAX traces
        return {n: x * scale * (i + 1) for i, n in enumerate(names)}

    g = cached_jit(f)
    out = g(np.arange(4.0), 2.0, ("a", "b"))
    print(len(TRACES), float(out["b"][3]))
""")


def _run(script, cache):
    env = {**os.environ, "MOTORID_CACHE_DIR": str(cache)}
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout.split()


def test_compiled_program_is_kept_on_disk_and_reloaded(tmp_path):
    script = tmp_path / "prog.py"
    script.write_text(SCRIPT)
    cache = tmp_path / "cache"
    assert _run(script, cache) == ["1", "12.0"]  # traced and compiled
    files = list((cache / "aot").rglob("f-*.bin"))
    assert len(files) == 1
    assert _run(script, cache) == ["0", "12.0"]  # loaded: no trace at all
    files[0].write_bytes(b"not an executable")  # a broken file is replaced, the answer is right
    assert _run(script, cache) == ["1", "12.0"]
    assert _run(script, cache) == ["0", "12.0"]


def test_cached_jit_matches_plain_jax_and_keys_on_static_values(tmp_path):
    import jax

    from motorid._aot import cached_jit

    def f(x, k, names):
        return {n: jax.numpy.sin(x) * k for n in names}

    g = cached_jit(f)
    x = np.linspace(0, 1, 5)
    for k in (1.0, 3.0):  # a static float is part of the key: a new value, a new program
        got = g(x, k, ("a",))
        np.testing.assert_allclose(np.asarray(got["a"]), np.sin(x) * k, rtol=1e-15)
    assert len(g._memory) == 2
    g(np.linspace(0, 1, 7), 1.0, ("a",))  # a new shape, a new program
    assert len(g._memory) == 3


def test_static_object_of_a_foreign_class_is_not_kept_on_disk(tmp_path, monkeypatch):
    from motorid import _aot

    class Setting:  # a user's class: its code is not in motorid's fingerprint
        def __repr__(self):
            return "<setting>"

    monkeypatch.setattr(_aot._jaxconfig, "CACHE_DIR", str(tmp_path))

    def f(x, setting):
        return x * 2.0

    g = _aot.cached_jit(f)
    np.testing.assert_allclose(np.asarray(g(np.ones(3), Setting())), 2.0)
    assert not list(tmp_path.rglob("*.bin"))
    g(np.ones(3), "plain text")  # a plain static value: kept
    assert len(list(tmp_path.rglob("f-*.bin"))) == 1




RELEASE_SCRIPT = textwrap.dedent("""
    import numpy as np
    from motorid._aot import cached_jit

    TRACES = []

    class Setting:  # a foreign static object: never on disk
        def __repr__(self):
            return "<setting>"

    def f(x, k):
        TRACES.append(1)
        return np.float64(0.7318) * x**3 - x * np.float64(1.9134)

    g = cached_jit(f)
    x = np.arange(5.0)
    first = np.asarray(g(x, "on disk"))
    g(x, Setting())
    held = len(g._memory)
    dropped = cached_jit.release_all()
    left = len(g._memory)
    again = np.asarray(g(x, "on disk"))
    print(held, dropped, left, len(TRACES), bool(np.array_equal(first, again)))
""")


def test_release_all_drops_only_what_the_disk_keeps(tmp_path):
    """Diagnose frees its programs between steps: a program kept on disk is dropped from memory
    and loads again with the same numbers, without tracing; one that exists only in memory
    (compiling it again would cost seconds) is kept.  In a fresh process: XLA shares the
    kernels of identical programs within one, and an executable whose kernels came from an
    earlier compile does not serialize whole (motorid._aot then compiles it again)."""
    script = tmp_path / "release.py"
    script.write_text(RELEASE_SCRIPT)
    held, dropped, left, traces, same = _run(script, tmp_path / "cache")
    assert (held, dropped, left) == ("2", "1", "1")
    assert traces == "2" and same == "True"  # loaded from disk: no third trace


TWIN_SCRIPT = textwrap.dedent("""
    import sys
    import jax.numpy as jnp
    import numpy as np
    from motorid._aot import cached_jit

    TRACES = []

    def f(x, tag):
        TRACES.append(1)  # runs only while JAX traces
        y = jnp.where(x > 1.5, jnp.sin(x) * 2.0, x + 1.0)  # the tag does not enter the program:
        return jnp.cumsum(y) @ jnp.outer(y, x)  # both keys lower alike

    jnp.sin(jnp.ones(3)).block_until_ready()  # an eager operation first: JAX turns its cache on
    g = cached_jit(f)
    for tag in sys.argv[1:]:
        out = g(np.arange(4.0), tag)
    print(len(TRACES), float(out[3]))
""")


def test_twin_programs_saved_from_one_process_load_in_the_next(tmp_path):
    # two keys whose programs are identical: the second came out of JAX's persistent compile
    # cache (filled by the first) unless motorid compiles past it (JAX decides on its first
    # compile whether it uses that cache, and keeps to it), and such an executable
    # serializes without its kernels ("Function ... not found" on its first run, then the file
    # is deleted and compiled again in memory: a trace in every later process)
    script = tmp_path / "twins.py"
    script.write_text(TWIN_SCRIPT)
    cache = tmp_path / "cache"
    env = {**os.environ, "MOTORID_CACHE_DIR": str(cache)}

    def run(*tags):
        proc = subprocess.run([sys.executable, str(script), *tags], capture_output=True, text=True, env=env,
                              timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        traces, value = proc.stdout.split()
        return int(traces), float(value)

    x = np.arange(4.0)
    y = np.where(x > 1.5, np.sin(x) * 2.0, x + 1.0)
    want = pytest.approx(float((np.cumsum(y) @ np.outer(y, x))[3]), rel=1e-12)
    assert run("first", "second") == (2, want)  # both traced and compiled, in one process
    assert len(list((cache / "aot").rglob("f-*.bin"))) == 2
    assert run("second") == (0, want)  # loaded, and it runs: no trace
    assert run("first") == (0, want)
    assert len(list((cache / "aot").rglob("f-*.bin"))) == 2


def test_cache_is_pruned_to_its_cap_oldest_first(tmp_path, monkeypatch):
    from motorid import _cachesize

    root = tmp_path / "cache"
    (root / "aot" / "v1").mkdir(parents=True)
    (root / "aot" / "v2").mkdir(parents=True)
    files = [root / f"jit_f-{i}-cache" for i in range(6)] + [root / "aot" / "v1" / "old.bin",
                                                             root / "aot" / "v2" / "new.bin"]
    for age, f in zip((90, 80, 70, 60, 50, 40, 100, 10), files):  # minutes ago
        f.write_bytes(b"x" * 100_000)
        t = 1_000_000.0 - age * 60
        os.utime(f, (t, t))
    for f in (root / "notes.txt", root / "aot" / "readme.txt", root / "sub" / "x-cache"):
        f.parent.mkdir(exist_ok=True)  # not cache entries (a folder shared by mistake): never touched
        f.write_bytes(b"y" * 1_000_000)
        os.utime(f, (1.0, 1.0))
    cap = 500_000  # the entries hold 800 000 bytes: down to 80 % of the cap, oldest first
    assert _cachesize.prune(root, cap) == 400_000
    left = sorted(p.name for p in root.rglob("*") if p.is_file() and p.read_bytes()[:1] == b"x")
    assert left == ["jit_f-3-cache", "jit_f-4-cache", "jit_f-5-cache", "new.bin"]
    assert all(f.exists() for f in (root / "notes.txt", root / "aot" / "readme.txt", root / "sub" / "x-cache"))
    for f in (root / "aot" / "readme.txt", root / "notes.txt"):
        f.unlink()
    assert not (root / "aot" / "v1").exists()  # an emptied folder goes too
    assert _cachesize.prune(root, cap) == 0  # under the cap: nothing

    # once a day, by the marker's age; MOTORID_CACHE_MAX_MB sets the cap, 0 lifts it
    monkeypatch.setenv("MOTORID_CACHE_MAX_MB", str(250_000 / 2**20))  # 400 000 bytes held: two go
    assert _cachesize.prune_now_and_then(root, now=2_000_000.0) == 200_000
    assert sorted(p.name for p in root.glob("*-cache")) == ["jit_f-5-cache"]
    assert _cachesize.prune_now_and_then(root, now=2_000_000.0 + 3600) == 0  # checked an hour ago
    (root / "a-cache").write_bytes(b"x" * 300_000)
    assert _cachesize.prune_now_and_then(root, now=2_000_000.0 + 2 * 86400) > 0
    monkeypatch.setenv("MOTORID_CACHE_MAX_MB", "0")
    assert _cachesize.max_bytes() is None and _cachesize.prune_now_and_then(root, now=3e6) == 0
    monkeypatch.setenv("MOTORID_CACHE_MAX_MB", "lots")  # never stops a run: the default
    assert _cachesize.max_bytes() == _cachesize.DEFAULT_MAX_MB * 2**20
    monkeypatch.setenv("MOTORID_CACHE_MAX_MB", "inf")
    assert _cachesize.max_bytes() is None


def test_a_jax_entry_goes_with_its_access_time_file(tmp_path):
    # JAX's own eviction reads the -atime file of every -cache file: the two go together, and an
    # entry another process deleted meanwhile counts as freed (no newer entry goes in its place)
    from motorid import _cachesize

    root = tmp_path / "cache"
    root.mkdir()
    for i, age in enumerate((30, 20, 10)):
        for suffix, size in (("-cache", 100_000), ("-atime", 8)):
            f = root / f"jit_g-{i}{suffix}"
            f.write_bytes(b"x" * size)
            os.utime(f, (1e6 - age * 60, 1e6 - age * 60))
    assert _cachesize.prune(root, 200_000) == 200_016  # 300 024 bytes → at most 160 000: two entries
    assert sorted(p.name for p in root.iterdir()) == ["jit_g-2-atime", "jit_g-2-cache"]
    entries = _cachesize._entries(root)
    assert len(entries) == 1 and entries[0][1] == 100_008


def test_a_pruned_program_is_compiled_again_and_a_loaded_one_marked_used(tmp_path):
    script = tmp_path / "prog.py"
    script.write_text(SCRIPT)
    cache = tmp_path / "cache"
    assert _run(script, cache) == ["1", "12.0"]
    (path,) = list((cache / "aot").rglob("f-*.bin"))
    os.utime(path, (1e6, 1e6))
    assert _run(script, cache) == ["0", "12.0"]  # loaded: its time says it was used now
    assert path.stat().st_mtime > 1e9
    path.unlink()  # pruned
    assert _run(script, cache) == ["1", "12.0"]


def test_motors_that_differ_only_in_their_numbers_share_one_compiled_program():
    """The spec's numbers (D, J, φ, the oil's) are inputs of a compiled program, not constants in
    it: a second motor with the same pistons and harmonics runs the first one's program, and each
    gets its own answer (the model evaluated with its own D and J)."""
    import dataclasses

    import jax

    from motorid import model
    from motorid._aot import cached_jit

    g = cached_jit(model.predict)
    a = model.MotorSpec("motor A", 9, 80e-6, inertia=0.005, leak_phase=0.35)
    b = dataclasses.replace(a, name="motor B", displacement=107e-6, inertia=0.02, leak_phase=0.3,
                            oil=dataclasses.replace(a.oil, nu40_cSt=32.0, name="VG 32"))
    n = 64
    theta, w = np.linspace(0.0, 6.0, n), np.linspace(-200.0, 300.0, n)
    p = model.default_parameters(a)
    for spec in (a, b):
        s = model.make_samples(spec, theta, w, np.full(n, 2e7), np.full(n, 1e6), np.full(n, 2e5),
                               np.full(n, 0.03), acceleration=np.linspace(-50.0, 50.0, n))
        got = np.array(g(model.as_jax(p), spec, s))
        want = np.array(jax.jit(lambda q, x: model.predict(q, spec, x))(model.as_jax(p), s))  # spec as constants
        assert np.all(np.isfinite(got))
        for i in range(4):  # torque, q_a, q_b, q_case
            np.testing.assert_allclose(got[i], want[i], rtol=1e-12, atol=1e-12 * np.max(np.abs(want[i])))
    assert len(g._memory) == 1  # one program for both motors
    other = np.array(g(model.as_jax(p), a, s))  # and it is not motor B's answer for A
    assert not np.allclose(other[0], got[0]) and not np.allclose(other[1], got[1])  # D, J: torque; D: port flow
