"""``~/identify_payload``'s fit in a process of its own, so that it cannot stretch the node's outputs.

The fit (:func:`._pipeline.fit_held`: a payload fit over up to ``identify_buffer`` s of samples, seconds of numpy
and casadi) would hold the interpreter's lock in the node's process for most of its run: the inputs' thread
would wait for it between messages. Here it runs in a child process (this module run as ``__main__``)
at a lower priority (``nice`` 10, set before its imports) and its linear algebra on one thread: the node's threads
keep their CPU; the fit takes what is left. The child is started with the node (:meth:`Worker.start`), so that its
imports (a second of CPU) are done before a call comes, and kept for the next ones; a cancelled call
(``~/cancel``) kills it (the next call starts another), as does the node stopping. Jobs and results go through its
standard input and output, pickled.
"""

import pickle
import select
import signal
import subprocess
import sys
import threading

from fmscal.plant.numerics import one_thread_environment

from ._pipeline import fit_held, motion_source

__all__ = ["Worker", "Cancelled", "main"]

#: The worker's niceness: below the node's threads, which must keep their CPU.
NICE = 10
#: The child's command: its niceness first, then the imports (seconds of CPU that must not compete with the node).
_LAUNCH = (f"import os; os.nice({NICE}); import runpy; "
           "runpy.run_module('fmscal.analysis.ros2._worker', run_name='__main__', alter_sys=True)")
#: s between two looks at a cancellation while the fit runs.
POLL = 0.05


class Cancelled(Exception):
    """The fit was cancelled (``~/cancel``) or the node is stopping."""


class Worker:
    """The fit's child process, seen from the node: :meth:`run` a job, :meth:`cancel` it from another thread."""

    def __init__(self):
        self._proc = None
        self._lock = threading.Lock()
        self._cancelled = threading.Event()
        self._closed = False                            # the node stopping: no fit starts after it
        self.running = False

    def start(self):
        """Start the child now (the node at its start), so that its imports are done before a call needs it."""
        with self._lock:
            if not self._closed:
                self._start()

    def _start(self):
        if self._proc is None or self._proc.poll() is not None:
            self._proc = subprocess.Popen([sys.executable, "-c", _LAUNCH],
                                          stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                          start_new_session=True,     # a Ctrl-C to the node's group is the node's
                                          env=one_thread_environment())   # the node keeps a core
        return self._proc

    def run(self, settings, job):
        """The result of :func:`._pipeline.fit_held` on ``job`` (the motion's source rebuilt from ``settings``).

        Raises
        ------
        Cancelled
            :meth:`cancel` was called meanwhile (the child killed).
        RuntimeError
            The child died or answered nothing (its cause in the message).
        """
        with self._lock:
            if self._closed:                            # closed before this call reached here: not started
                raise Cancelled()
            self._cancelled.clear()
            proc = self._start()
            self.running = True
        try:
            data = pickle.dumps((settings, job), protocol=pickle.HIGHEST_PROTOCOL)
            writer = threading.Thread(target=_write, args=(proc, data), daemon=True)
            writer.start()                           # the child reads once its imports are done
            out = proc.stdout
            while True:
                if self._cancelled.is_set():
                    raise Cancelled()
                ready, _, _ = select.select([out], [], [], POLL)
                if ready:
                    break
            try:
                result = pickle.load(out)
            except (EOFError, pickle.UnpicklingError) as err:
                if self._cancelled.is_set():
                    raise Cancelled() from None
                raise RuntimeError(f"the fit's process ended (status {proc.poll()}): {err or 'no answer'}") from None
            return result
        finally:
            self.running = False

    def cancel(self):
        """Kill the running fit (its :meth:`run` raises :class:`Cancelled`); True where one was running."""
        with self._lock:
            running = self.running
            self._cancelled.set()
            if running:
                self._kill()
            return running

    def close(self):
        """Kill the child (the node stopping); a :meth:`run` called after it raises :class:`Cancelled`."""
        with self._lock:
            self._closed = True
            self._cancelled.set()
            self._kill()

    def _kill(self):
        proc, self._proc = self._proc, None
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait(timeout=5)


def _write(proc, data):
    try:
        proc.stdin.write(data)
        proc.stdin.flush()
    except (BrokenPipeError, OSError, ValueError):       # killed meanwhile: run() says so
        pass


def _die_with_parent():
    """Linux: this process killed when its parent dies (the node killed outright leaves no fit behind)."""
    try:
        import ctypes
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)     # PR_SET_PDEATHSIG
    except Exception:
        pass


def main():
    """The child: take pickled ``(settings, job)`` from standard input, answer :func:`._pipeline.fit_held`'s
    result (or a failure's message) pickled on standard output; until standard input closes."""
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)         # the node decides
    stdin, stdout = sys.stdin.buffer, sys.stdout.buffer
    while True:
        try:
            settings, job = pickle.load(stdin)
        except EOFError:
            return
        try:
            result = fit_held(job, motion_source(settings))
        except Exception as err:                         # a bug: said in the answer, the node kept up
            first = str(err).splitlines()[0] if str(err) else ""
            result = dict(ok=False, payload=None, message=f"identify_payload failed: {type(err).__name__}: {first}")
        pickle.dump(result, stdout, protocol=pickle.HIGHEST_PROTOCOL)
        stdout.flush()


if __name__ == "__main__":
    main()
