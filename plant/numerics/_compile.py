"""Compile casadi functions to C once, and call them through numpy buffers.

casadi's own virtual machine interprets a function one operation at a time;
the same function generated as C and built by the system C compiler runs
faster (how much: ``fmscal bench``, docs/speed.md). :func:`compile_function` does that
(``-O3`` for this machine's processor, without fast-math or fused
multiply-adds), caching the shared library by the hash of its source and the
processor (``FMSCAL_CACHE`` or ``~/.cache/fmscal``; processes that need the
same library at once build it once, under a file lock), and falls back to the
virtual machine, with one warning, where no compiler is found. ``FMSCAL_COMPILER=none`` asks for the virtual
machine; ``FMSCAL_COMPILER=gcc`` (or ``cc``, ``clang``) names the compiler.

:class:`BufferedCall` binds numpy arrays to a function's inputs and outputs
(``casadi.Function.buffer()``): a call then costs no conversion at all.
"""

import contextlib
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import casadi as ca
import numpy as np

try:
    import fcntl
except ImportError:                       # Windows
    fcntl = None

__all__ = ["compile_function", "compile_functions", "compiler", "BufferedCall", "ChunkedSteps", "build_once"]

# no -ffast-math and no fused multiply-adds (-ffp-contract=off): the C code rounds each operation as numpy does
_FLAGS = ("-O3", "-ffp-contract=off", "-fPIC", "-shared")
# this machine's instruction set (faster code on the larger steps); dropped where the compiler refuses it
_NATIVE = ("-march=native",)
# generated C beyond this many characters is built at -O1: on megabytes of straight-line code (the spatial EKF's
# step) -O3 costs a fresh machine a much longer build for little run time (the figures: docs/speed.md)
_LARGE_SOURCE = 1_000_000
# a loop that keeps only its last state (ChunkedSteps(keep_states=False)) writes out this many steps one after
# another, and repeats that block (casadi mapaccum) for longer loops: a long loop written out is slow to build
_UNROLLED = 10
_loaded = {}                               # source hash -> casadi.Function, this process
_warned = []


def compiler():
    """The C compiler :func:`compile_function` uses, or None for casadi's virtual machine.

    Returns
    -------
    str or None
        A path to ``FMSCAL_COMPILER`` (default the first of ``cc``, ``gcc``,
        ``clang`` found), or None when ``FMSCAL_COMPILER=none`` or none is found.
    """
    name = os.environ.get("FMSCAL_COMPILER", "").strip()
    if name.lower() in ("none", "vm", "0"):
        return None
    candidates = [name] if name else ["cc", "gcc", "clang"]
    for c in candidates:
        path = shutil.which(c)
        if path:
            return path
    return None


def _cache_dir():
    root = os.environ.get("FMSCAL_CACHE") or Path.home() / ".cache" / "fmscal"
    path = Path(root)
    path.mkdir(parents=True, exist_ok=True)
    return path


def _machine():
    """The instruction set a library built with ``-march=native`` needs (the cache may be shared across machines)."""
    try:
        with open("/proc/cpuinfo") as f:
            return next((line for line in f if line.startswith("flags")), platform.machine())
    except OSError:
        return platform.processor() or platform.machine()


def compile_function(fun):
    """``fun`` generated as C and compiled, or ``fun`` itself without a compiler.

    Parameters
    ----------
    fun : casadi.Function

    Returns
    -------
    casadi.Function
        Same inputs, outputs and results (to rounding: no fast-math).
    """
    return compile_functions([fun])[0]


def compile_functions(funs):
    """Several casadi functions generated as C into one library, compiled once (:func:`compile_function`).

    Functions that call the same function (the loops of one step,
    :class:`ChunkedSteps`) share its code and its build.

    Parameters
    ----------
    funs : sequence of casadi.Function
        Distinct names.

    Returns
    -------
    list of casadi.Function
        The compiled functions in the order given, or ``funs`` themselves without a compiler.
    """
    funs = list(funs)
    cc = compiler()
    if cc is None:
        return funs
    name = funs[0].name()
    gen = ca.CodeGenerator(f"{name}.c")
    for fun in funs:
        gen.add(fun)
    source = gen.dump()
    flags = ("-O1", *_FLAGS[1:]) if len(source) > _LARGE_SOURCE else _FLAGS
    key = hashlib.sha256((source + cc + " ".join(flags + _NATIVE) + _machine()).encode()).hexdigest()[:20]
    if key in _loaded:
        return list(_loaded[key])
    try:
        directory = _cache_dir()
        library = directory / f"{name}_{key}.so"
        if not library.exists():
            with _build_lock(directory / f"{name}_{key}.lock"):
                if not library.exists():          # built by another process while this one waited
                    _build(cc, flags, source, name, directory, library)
        compiled = [ca.external(fun.name(), str(library)) for fun in funs]
    except (OSError, subprocess.CalledProcessError, RuntimeError) as err:
        if not _warned:
            detail = getattr(err, "stderr", "") or str(err)
            warnings.warn(f"fmscal: C compilation failed ({detail.strip()[:200]}); "
                          "using casadi's virtual machine", RuntimeWarning, stacklevel=3)
            _warned.append(True)
        return funs
    _loaded[key] = compiled
    return list(compiled)


@contextlib.contextmanager
def _build_lock(path):
    """Hold an exclusive lock on ``path`` (POSIX ``flock``): parallel processes (test workers, a sweep's workers)
    that need the same library on a fresh machine build it once, the others wait for it. Without ``fcntl``
    (Windows), or where the lock cannot be taken (a file system without locks, a lock file another user
    owns), no lock: each builds its own copy and the atomic rename keeps the cache whole."""
    if fcntl is None:
        yield
        return
    try:
        handle = open(path, "a")
    except OSError:                       # a lock file another user owns, a read-only cache
        handle = None
    if handle is not None:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX)
        except OSError:                   # a file system without locks (NFS without lockd)
            handle.close()
            handle = None
    try:
        yield                             # unlocked where no lock was taken: the atomic rename keeps the cache whole
    finally:
        if handle is not None:
            fcntl.flock(handle, fcntl.LOCK_UN)
            handle.close()


def _build(cc, flags, source, name, directory, library):
    """Compile ``source`` into the shared library ``library`` (written whole, by an atomic rename)."""
    with tempfile.TemporaryDirectory(dir=directory) as tmp:
        src = Path(tmp) / f"{name}.c"
        src.write_text(source)
        out = Path(tmp) / "lib.so"
        try:
            subprocess.run([cc, *flags, *_NATIVE, str(src), "-o", str(out), "-lm"], check=True,
                           capture_output=True, text=True)
        except subprocess.CalledProcessError:       # a compiler without -march=native
            subprocess.run([cc, *flags, str(src), "-o", str(out), "-lm"], check=True,
                           capture_output=True, text=True)
        os.replace(out, library)          # atomic: a reader never sees half a library


def build_once(cache, key, build, limit):
    """``cache[key]``, made by ``build()`` the first time: a process's compiled steps, one build per key.

    Parameters
    ----------
    cache : dict
    key : hashable
    build : callable
        ``build()``: the value (a :class:`ChunkedSteps`), called only where ``key`` is missing.
    limit : int
        The cache is emptied when it holds this many, so that a long sweep over settings does not keep
        every build.

    Returns
    -------
    object
        ``cache[key]``.
    """
    if key not in cache:
        if len(cache) >= limit:
            cache.clear()
        cache[key] = build()
    return cache[key]


class BufferedCall:
    """A casadi function bound to numpy arrays (``casadi.Function.buffer()``).

    Write the inputs into :attr:`inputs`, call, read :attr:`outputs`. Arrays
    are in casadi's column-major order: an ``(r, c)`` casadi matrix is a
    C-ordered numpy array of shape ``(c, r)``.

    Parameters
    ----------
    fun : casadi.Function
        Every input and output dense.

    Attributes
    ----------
    inputs, outputs : list of ndarray
        One flat float64 array per input and per output.
    """

    def __init__(self, fun):
        self.fun = fun
        self._buffer, self._trigger = fun.buffer()
        self.inputs = [np.zeros(fun.nnz_in(i)) for i in range(fun.n_in())]
        self.outputs = [np.zeros(fun.nnz_out(i)) for i in range(fun.n_out())]
        for i in range(fun.n_in()):
            if fun.nnz_in(i) != fun.numel_in(i):
                raise ValueError(f"input {i} of {fun.name()} must be dense; got {fun.sparsity_in(i).dim()}"
                                 f" with {fun.nnz_in(i)} nonzeros")
            self._buffer.set_arg(i, memoryview(self.inputs[i]))
        for i in range(fun.n_out()):
            if fun.nnz_out(i) != fun.numel_out(i):
                raise ValueError(f"output {i} of {fun.name()} must be dense; got {fun.sparsity_out(i).dim()}"
                                 f" with {fun.nnz_out(i)} nonzeros")
            self._buffer.set_res(i, memoryview(self.outputs[i]))

    def __call__(self):
        self._trigger()


class ChunkedSteps:
    """A one-step recursion ``z_{k+1} = f(z_k, a_k, b_k, ...)`` run over many steps in compiled chunks.

    ``f`` is accumulated over ``chunk`` steps (casadi ``mapaccum``), compiled
    once (:func:`compile_function`) and called through buffers
    (:class:`BufferedCall`). The simulator, every recursive observer and the
    maximum-likelihood filter run through this one loop.

    Parameters
    ----------
    step : casadi.Function
        ``z_next, *y = step(z, a, b, ...)``: first input and first output
        the state (dense column), the other inputs those of each step, the
        other outputs (optional) per-step values that are not carried on.
    chunk : int
        Steps per compiled call.
    keep_states : bool
        True (default): the compiled chunk returns the state after each of its
        steps. False: only the state after its last one, and the per-step
        outputs, so that a large state is not written out after every step;
        then only ``run(states=False)``, and the steps past the last whole
        chunk (and those a health test keeps of a chunk) run through loops of
        a tenth, a hundredth, ... of the chunk, down to one step, built into
        the same library.
    """

    def __init__(self, step, chunk, keep_states=True):
        self.chunk = int(chunk)
        self.keep_states = bool(keep_states)
        self.nz = step.nnz_in(0)
        self.sizes = [step.nnz_in(i) for i in range(1, step.n_in())]
        self.out_sizes = [step.nnz_out(i) for i in range(1, step.n_out())]
        if self.keep_states:
            self.fun = compile_function(step.mapaccum(f"{step.name()}_chunk", self.chunk))
            return
        lengths = [self.chunk]
        while lengths[-1] > 1:
            lengths.append(max(lengths[-1] // 10, 1))
        loops = compile_functions([_last_state_loop(step, k, f"{step.name()}_last{k}") for k in lengths])
        self._loops = list(zip(lengths, loops))
        self.fun = loops[0]

    def run(self, z0, inputs, healthy=None, outputs=False, states=True, progress=None, with_start=False):
        """Run the recursion from ``z0`` over the rows of ``inputs``.

        Parameters
        ----------
        z0 : ndarray, shape (nz,)
        inputs : list of ndarray, each shape (N, size_i)
            Row ``k`` of each is the step's input from state ``k`` to ``k + 1``.
        healthy : callable, optional
            ``healthy(Z_chunk, k0) -> int`` (``k0`` the step of the chunk's first
            row): the number of leading rows of a
            finished chunk to keep; the run stops after a chunk that keeps
            fewer than it computed. With ``states=False`` it is given the
            chunk's rows of the first other output instead of the states.
        outputs : bool
            Also return the step's other outputs.
        states : bool
            Keep every state (default); False keeps only the last (the one
            after the last kept step), for a large state whose history is not wanted.
        progress : callable, optional
            ``progress(steps)`` after each chunk, with the steps it ran (a progress bar's ``update``).
        with_start : bool
            Put ``z0`` in the first row of the states (``M + 1`` rows), saving a copy.

        Returns
        -------
        Z : ndarray, shape (M, nz), or shape (nz,) with ``states=False``
            The states after each step (``M = N``, fewer if ``healthy`` stopped
            it), or the last one.
        Y : list of ndarray, each shape (M, size), only with ``outputs=True``
            The step's other outputs, row ``k`` from step ``k``.
        """
        if not self.keep_states:
            if states:
                raise ValueError("a ChunkedSteps built with keep_states=False runs with states=False only")
            z, Y = self._run_last(z0, inputs, healthy, progress)
            return (z, Y) if outputs else z
        n = len(inputs[0]) if inputs else 0
        call = BufferedCall(self.fun)              # buffers of this run: safe across threads
        z_in, *u_in = call.inputs
        u_in = [buf.reshape(self.chunk, size) for buf, size in zip(u_in, self.sizes)]    # column-major
        Z_out, *Y_out = [buf.reshape(self.chunk, size) for buf, size in zip(call.outputs, [self.nz, *self.out_sizes])]
        first = 1 if (states and with_start) else 0
        Z_all = np.empty((n + first if states else 1, self.nz))
        Z_all[0] = z0
        Z = Z_all[first:]
        Y = [np.empty((n, size)) for size in self.out_sizes]
        z_in[:] = z0
        m = n
        for k0 in range(0, n, self.chunk):
            k1 = min(k0 + self.chunk, n)
            for buf, values in zip(u_in, inputs):
                buf[:k1 - k0] = values[k0:k1]
                buf[k1 - k0:] = values[k1 - 1]            # padding past the end, discarded
            call()
            if progress is not None:
                progress(k1 - k0)
            for y, y_out in zip(Y, Y_out):
                y[k0:k1] = y_out[:k1 - k0]
            if states:
                Z[k0:k1] = Z_out[:k1 - k0]
            keep = k1 - k0 if healthy is None else healthy((Z if states else Y[0])[k0:k1], k0)
            if keep:
                z_in[:] = Z_out[keep - 1]
            if keep < k1 - k0:
                m = k0 + keep
                break
        if not states:
            Z = z_in.copy() if n else np.array(z0, dtype=float)
        else:
            Z = Z_all[:first + m]
        return (Z, [y[:m] for y in Y]) if outputs else Z

    def _run_last(self, z0, inputs, healthy, progress):
        """:meth:`run` with ``states=False`` on the loops of ``keep_states=False``: the last state, the outputs."""
        n = len(inputs[0]) if inputs else 0
        calls = [(k, BufferedCall(fun)) for k, fun in self._loops]      # buffers of this run: safe across threads
        Y = [np.empty((n, size)) for size in self.out_sizes]
        z = np.array(z0, dtype=float)
        m = n
        for k0 in range(0, n, self.chunk):
            k1 = min(k0 + self.chunk, n)
            z_next = self._advance(calls, z, inputs, k0, k1, Y)
            if progress is not None:
                progress(k1 - k0)
            keep = k1 - k0 if healthy is None else healthy(Y[0][k0:k1], k0)
            if keep < k1 - k0:                  # the state after the kept steps: run them again
                z, m = self._advance(calls, z, inputs, k0, k0 + keep, None), k0 + keep
                break
            z = z_next
        return z, [y[:m] for y in Y]

    def _advance(self, calls, z, inputs, k0, k1, Y):
        """The state after steps ``k0 .. k1 - 1`` from ``z``, through the longest loops that fit; their
        outputs written to rows ``k0 .. k1 - 1`` of ``Y`` (None: not kept)."""
        z = np.array(z, dtype=float)
        for k, call in calls:
            z_in, *u_in = call.inputs
            z_out, *y_out = call.outputs
            while k1 - k0 >= k:
                z_in[:] = z
                for buf, values, size in zip(u_in, inputs, self.sizes):
                    buf.reshape(k, size)[:] = values[k0:k0 + k]           # column-major: one row per step
                call()
                if Y is not None:
                    for y, buf, size in zip(Y, y_out, self.out_sizes):
                        y[k0:k0 + k] = buf.reshape(k, size)
                z[:] = z_out
                k0 += k
        return z


def _last_state_loop(step, length, name):
    """``step`` run ``length`` times: the state after the last step and every step's other outputs.

    The ``mapaccum`` of ``step`` without the states between (:class:`ChunkedSteps`, ``keep_states=False``):
    the same inputs, the first output the state, the others ``(size, length)``. Up to :data:`_UNROLLED`
    steps are written out one after another; a longer loop is a ``mapaccum`` of such blocks, which writes
    out only every block's last state and builds in a fraction of the time of the steps written out.
    """
    z0 = ca.MX.sym("z", step.sparsity_in(0))
    rows = [ca.MX.sym(f"u{i}", step.nnz_in(i), length) for i in range(1, step.n_in())]
    if length > _UNROLLED and length % _UNROLLED == 0:
        blocks = _last_state_loop(step, _UNROLLED, f"{name}_block").mapaccum(f"{name}_blocks", length // _UNROLLED)
        Z, *Y = blocks.call([z0, *rows])           # a block's inputs and outputs: _UNROLLED columns each, in turn
        return ca.Function(name, [z0, *rows], [Z[:, -1], *Y])
    z, outputs = z0, []
    for k in range(length):
        z, *y = step.call([z, *[r[:, k] for r in rows]])
        outputs.append(y)
    return ca.Function(name, [z0, *rows], [z, *[ca.horzcat(*col) for col in zip(*outputs)]])
