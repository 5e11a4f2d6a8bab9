"""Compiled functions kept on disk, so that a second CLI run neither traces nor compiles.

JAX's persistent compilation cache (:mod:`motorid._jaxconfig`) saves the XLA
compile, but every fresh process still traces the Python function and lowers it
to HLO before it can even look the compile up: for the fit's few functions that
is over a second per ``motorid fit``.  :func:`cached_jit` keeps the *compiled
executable* instead (``jax.experimental.serialize_executable``), keyed by
everything the program depends on:

- the function's name and the source of the whole motorid package (any edit
  makes new keys), the jax/jaxlib versions and the device;
- the static part of the arguments (everything that is not an array: the motor
  spec, parameter names, tolerances), by ``repr``;
- the shapes and dtypes of the array arguments (arrays are padded to powers of
  two by the callers, so few shapes occur).

Semantics are those of ``equinox.filter_jit``: arrays (NumPy or JAX) are traced,
every other leaf is static.  Outputs must be pytrees of arrays.  Anything that
cannot be kept safely — a static argument whose ``repr`` holds a memory address
or whose class is not motorid's (its code is not in the fingerprint), a program
with a host callback, a cache folder that cannot be written, a file
that does not load — falls back to compiling in memory, with the same result.
Files live in ``$MOTORID_CACHE_DIR/aot/<source version>/`` beside the XLA
cache (30-200 kB each); the folders of all but the last few source versions are
removed as new ones appear; delete the folder to clear them.  The files are
pickles and executable code: the folder must be the user's own, like any cache.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import platform
import threading
from pathlib import Path

import jax
import numpy as np

from motorid import _jaxconfig

_PACKAGE = Path(__file__).resolve().parent
_version: str | None = None


def _fingerprint() -> str:
    """Hash of the motorid sources, the JAX versions and the machine the executables run on."""
    global _version
    if _version is None:
        h = hashlib.sha256()
        for path in sorted(_PACKAGE.rglob("*.py")):
            h.update(str(path.relative_to(_PACKAGE)).encode())
            h.update(path.read_bytes())
        import jaxlib

        device = jax.devices()[0]
        h.update(f"{jax.__version__} {jaxlib.__version__} {device.platform} {device.device_kind} "
                 f"{platform.machine()} {_cpu_flags()}".encode())
        _version = h.hexdigest()
    return _version


def _cpu_flags() -> str:
    """The host CPU's feature flags (an executable compiled for AVX-512 must not load elsewhere)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith(("flags", "Features")):
                    return line.strip()
    except OSError:
        pass
    return platform.processor()


def _is_array(x) -> bool:
    return isinstance(x, (np.ndarray, jax.Array))


_KNOWN_MODULES = ("motorid", "builtins", "numpy")


def _keyable(x) -> bool:
    """Whether a static argument's repr identifies it: plain values, and objects of
    motorid's own classes (whose code the source fingerprint covers).  An object of
    a class defined elsewhere (a user's mechanism) could change behind the same repr."""
    return x is None or type(x).__module__.split(".")[0] in _KNOWN_MODULES


KEEP_VERSIONS = 4  # folders of other source versions kept (other checkouts may share the cache)


def _folder() -> Path | None:
    """This source version's folder; made on first use, when the oldest other versions go."""
    root = Path(_jaxconfig.CACHE_DIR) / "aot"
    folder = root / _fingerprint()[:20]
    try:
        if not folder.is_dir():
            folder.mkdir(parents=True, exist_ok=True)
            others = sorted((p for p in root.iterdir() if p.is_dir() and p != folder),
                            key=lambda p: p.stat().st_mtime, reverse=True)
            for old in others[KEEP_VERSIONS:]:
                for f in old.iterdir():
                    f.unlink(missing_ok=True)
                old.rmdir()
            for stray in root.glob("*.bin"):  # files of the flat layout of earlier versions
                stray.unlink(missing_ok=True)
    except OSError:
        return None
    return folder if os.access(folder, os.W_OK) else None


_lapack_ready = False


def _load(path: Path):
    """A compiled executable from disk, or None."""
    global _lapack_ready
    from jax.experimental import serialize_executable

    try:
        data, in_tree, out_tree, uses_lapack = pickle.loads(path.read_bytes())
        if uses_lapack and not _lapack_ready:
            # the LAPACK kernels (QR, Cholesky, eigh) register with XLA on the first
            # lowering that needs them; a deserialized program skips that step
            from jax._src.lax.linalg import initialize_lapack

            initialize_lapack()
            _lapack_ready = True
        loaded = serialize_executable.deserialize_and_load(data, in_tree, out_tree)
    except Exception:  # noqa: BLE001 - a stale or foreign file: compile instead
        return None
    try:  # its modification time says when it was last used (motorid._cachesize prunes by it)
        os.utime(path)
    except OSError:
        pass
    return loaded


def _save(path: Path, compiled, hlo_text: str) -> None:
    if "callback" in hlo_text:  # a host callback points into this process: not portable
        return
    from jax.experimental import serialize_executable

    from motorid._atomic import write_bytes_atomic

    try:
        data, in_tree, out_tree = serialize_executable.serialize(compiled)
        write_bytes_atomic(path, pickle.dumps((data, in_tree, out_tree, "lapack" in hlo_text)))
    except Exception:  # noqa: BLE001 - not serializable or not writable: memory only
        pass


_LIBC: list = []  # the C library, looked up once (find_library runs a subprocess)


def trim_heap(collect: bool = True) -> None:
    """Return freed heap pages to the system (glibc's ``malloc_trim``; elsewhere nothing): the
    executables of XLA are freed into the C heap, which keeps them resident otherwise.  ``collect``:
    first a full garbage collection (for what only cycles hold; 70-90 ms with diagnose's objects
    alive, so diagnose's many steps leave it to the one before its final fit)."""
    import gc

    if collect:
        gc.collect()
    if not _LIBC:
        import ctypes
        import ctypes.util

        try:
            _LIBC.append(getattr(ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6"), "malloc_trim", None))
        except OSError:
            _LIBC.append(None)
    if _LIBC[0] is not None:
        _LIBC[0](0)


class cached_jit:  # noqa: N801 - used as a decorator, like jax.jit
    """``equinox.filter_jit`` whose compiled programs persist across processes (module docstring)."""

    _instances: list = []  # every cached_jit of the process (for release)

    def __init__(self, fun):
        self.fun = fun
        self.name = f"{fun.__module__}.{fun.__qualname__}"
        self._memory: dict = {}
        self._files: dict = {}  # key → its file on disk, where it has one
        cached_jit._instances.append(self)
        self.__wrapped__ = fun
        self.__doc__ = fun.__doc__

    def __call__(self, *args):
        leaves, treedef = jax.tree_util.tree_flatten(args)
        dynamic = [i for i, x in enumerate(leaves) if _is_array(x)]
        static = tuple(None if _is_array(x) else x for x in leaves)
        avals = tuple((np.shape(leaves[i]), str(leaves[i].dtype), bool(getattr(leaves[i], "weak_type", False)))
                      for i in dynamic)
        key = (treedef, static, avals)
        try:
            compiled = self._memory.get(key)
        except TypeError:  # an unhashable static leaf: no caching at all
            return jax.jit(lambda dyn: self._call_flat(dyn, leaves, dynamic, treedef))(
                [leaves[i] for i in dynamic])
        dyn = [leaves[i] for i in dynamic]
        if compiled is None:
            compiled, path = self._compile(key, leaves, dynamic, treedef)
            if path is not None:  # loaded from disk: its first run must succeed, else compile afresh
                try:
                    out = jax.block_until_ready(compiled(dyn))
                except Exception:  # noqa: BLE001 - a broken file
                    path.unlink(missing_ok=True)
                    compiled, _ = self._compile(key, leaves, dynamic, treedef, use_disk=False)
                    out = compiled(dyn)
                self._memory[key] = compiled
                return out
            self._memory[key] = compiled
        return compiled(dyn)

    @classmethod
    def release(cls, static_object) -> int:
        """Drop from memory every compiled program one of whose static arguments is
        ``static_object`` (a mechanism tried once, by diagnose): its executable is freed; a
        later call loads it from disk again → how many were dropped."""
        dropped = 0
        for inst in cls._instances:
            for key in [k for k in inst._memory if any(x is static_object for x in k[1])]:
                del inst._memory[key]
                dropped += 1
        return dropped

    @classmethod
    def release_all(cls, collect: bool = True) -> int:
        """Drop from memory every compiled program that is kept on disk, and hand the freed heap
        back to the system (each executable holds a few MB; a later call loads it from disk
        again, in milliseconds; a program only in memory stays, as compiling it again would
        cost seconds; ``collect``: as :func:`trim_heap`'s) → how many were dropped."""
        dropped = 0
        for inst in cls._instances:
            for key in [k for k in inst._memory if k in inst._files and inst._files[k].exists()]:
                del inst._memory[key]
                dropped += 1
        if dropped:
            trim_heap(collect)
        return dropped

    def _call_flat(self, dyn, leaves, dynamic, treedef):
        full = list(leaves)
        for i, x in zip(dynamic, dyn):
            full[i] = x
        return self.fun(*jax.tree_util.tree_unflatten(treedef, full))

    def _compile(self, key, leaves, dynamic, treedef, use_disk=True):
        """(compiled program, the file it was loaded from or None)."""
        treedef_, static, avals = key
        text = repr((self.name, str(treedef_), static, avals))
        portable = use_disk and " at 0x" not in text and all(_keyable(x) for x in static)
        folder = _folder() if portable else None
        path = None
        if folder is not None:
            digest = hashlib.sha256(text.encode()).hexdigest()[:40]
            path = folder / f"{self.fun.__name__}-{digest}.bin"
            self._files[key] = path
            if path.exists():
                loaded = _load(path)
                if loaded is not None:
                    return loaded, path
        skeleton = list(leaves)
        for i in dynamic:  # the traced function must not hold on to this call's data
            skeleton[i] = None
        lowered = jax.jit(lambda dyn: self._call_flat(dyn, skeleton, dynamic, treedef)).lower(
            [jax.ShapeDtypeStruct(np.shape(leaves[i]), leaves[i].dtype,
                                  weak_type=bool(getattr(leaves[i], "weak_type", False))) for i in dynamic])
        if path is None:
            return lowered.compile(), None
        # an executable that came out of JAX's persistent compile cache serializes without
        # its kernels (it loads, then fails on its first run: "Function ... not found"):
        # compile this one afresh (once; later runs load it from disk)
        compiled = _compile_afresh(lowered)
        _save(path, compiled, lowered.as_text())
        return compiled, None


_AFRESH = threading.Lock()  # one at a time: the setting and the cache's state are global


def _compile_afresh(lowered):
    """``lowered.compile()`` past JAX's persistent compile cache.  JAX decides once per process
    whether it uses that cache (``compilation_cache.is_cache_used`` latches its first answer), so
    turning the option off is not enough: the cache's state is reset on the way in and out."""
    from jax.experimental.compilation_cache import compilation_cache as cc

    with _AFRESH:
        enabled = jax.config.jax_enable_compilation_cache
        try:
            jax.config.update("jax_enable_compilation_cache", False)
            cc.reset_cache()
            return lowered.compile()
        finally:
            jax.config.update("jax_enable_compilation_cache", enabled)
            cc.reset_cache()
