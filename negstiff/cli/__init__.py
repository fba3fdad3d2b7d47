"""The ``negstiff`` command line: a thin shell over ``negstiff.models``, ``negstiff.inference`` and
``negstiff.report`` and ``negstiff.experiments`` (``docs/contract.md`` is its specification): ``parser`` (the
arguments), ``commands`` (one function per command), ``common`` (input errors, system files, result
JSON, the checks made before any work).

Exit codes: 0 success, 2 bad input (one line on stderr, no output written).
"""

from __future__ import annotations

import os
import signal
import sys


def _is_the_command() -> bool:
    """Whether this process is the ``negstiff`` command (the console script or ``python -m negstiff``), as
    opposed to a program or a test importing the library, or a section process of ``reproduce`` (its
    ``__main__`` is ``__mp_main__``, and it ignores Ctrl-C: its parent answers for it).
    """
    main = sys.modules.get("__main__")
    if getattr(main, "__name__", "__main__") != "__main__":
        return False
    spec = getattr(main, "__spec__", None)
    if spec is not None and spec.name == "negstiff.__main__":
        return True
    name = os.path.basename(getattr(main, "__file__", None) or "")
    for suffix in ("-script.pyw", "-script.py", ".exe"):  # the console script's spellings (setuptools)
        name = name.removesuffix(suffix)
    return name == "negstiff"


def _exit_at_once(signum, frame) -> None:
    """Ctrl-C or a kill before the command has started: one line and the exit code (130, 143); nothing
    has been written yet.
    """
    what, code = ("interrupted", 130) if signum == signal.SIGINT else ("terminated", 143)
    sys.stderr.write(f"negstiff: {what} (nothing written)\n")
    sys.stderr.flush()
    os._exit(code)


# Ctrl-C from the first millisecond: the handler is in place before the heavy imports below (numpy, the
# parser's modules: about a second, during which Python's own KeyboardInterrupt printed a traceback).
# Only the command installs it, and only where Python's default is still in place (a signal ignored by the
# parent stays ignored)
if _is_the_command():
    for _signum in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(_signum) in (signal.default_int_handler, signal.SIG_DFL):
            signal.signal(_signum, _exit_at_once)

import contextlib  # noqa: E402 (after the interrupt handler, on purpose)
import threading  # noqa: E402
import warnings  # noqa: E402
from collections.abc import Sequence  # noqa: E402

from negstiff.files import transaction  # noqa: E402
from negstiff.resources import limit_threads, usable_cores  # noqa: E402

from .common import InputError, bad_input_types, check_paths, write_json  # noqa: E402, F401 (API)
from .parser import build_parser, command_of  # noqa: E402


class _Terminated(BaseException):
    """A kill (SIGTERM) while the command's worker processes run: raised in the main thread so that the pool
    that started them stops them and releases its queues on the way out (``reproduce._run_pool``).
    """


def _interrupt_handler(command: str, what: str, code: int):
    """Ctrl-C (SIGINT) or a kill (SIGTERM): one line, the outputs being written removed, exit at once
    (130, 143). (Raising KeyboardInterrupt is not enough: emcee prints the traceback of any exception
    inside a log-probability call before passing it on.) A kill while worker processes run (reproduce's
    sections) is raised instead (``_Terminated``), in this process where no emcee runs: the pool ends its
    processes and releases its queues, then ``main`` prints the line (a kill of the command alone, not its
    group, had left them running).
    """

    def handler(signum, frame):
        import multiprocessing

        from negstiff.files import remove_pending

        if signum == signal.SIGTERM and multiprocessing.active_children():
            raise _Terminated  # main removes what was being written once the pool has stopped
        remove_pending()
        sys.stderr.write(f"negstiff {command}: {what} (nothing written)\n")
        sys.stderr.flush()
        os._exit(code)

    return handler


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser(only=command_of(sys.argv[1:] if argv is None else argv) or "")
    try:
        args = parser.parse_args(argv)
    except KeyboardInterrupt:
        print("negstiff: interrupted", file=sys.stderr)
        return 130
    if threading.current_thread() is threading.main_thread() and argv is None:  # the installed command
        signal.signal(signal.SIGINT, _interrupt_handler(args.command, "interrupted", 130))
        signal.signal(signal.SIGTERM, _interrupt_handler(args.command, "terminated", 143))
    try:
        check_paths(args)
        # a command's outputs (a record and its truth, a result and its figure) land together or not at
        # all; reproduce's report is one folder already, and its section cache must be readable at once
        group = transaction() if args.command != "reproduce" else contextlib.nullcontext()
        # one level of parallelism at a time, sized by the settings and never by the machine's load: BLAS (and
        # OpenMP) on one thread for the command, as an estimator's fit runs it from any entry (resources.
        # FIT_BLAS_THREADS: a sum split over threads is added in another order, and the numbers had moved with
        # the load average), negstiff's own threads (simulator batches, posterior ensembles: their parts are
        # independent) on the cores this process may use; an in-process caller gets its own back
        with warnings.catch_warnings(), group, limit_threads(1, own=usable_cores()):
            # the libraries' notices (arviz's dimension names, numpy's empty slices) are not the user's
            # business; negstiff's own warnings are in the result and on stderr (``warn``)
            warnings.simplefilter("ignore")
            return args.func(args)
    except bad_input_types() as exc:
        msg = " ".join(str(exc).split()) or type(exc).__name__
        print(f"negstiff {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"negstiff {args.command}: interrupted (nothing written)", file=sys.stderr)
        return 130
    except _Terminated:
        from negstiff.files import remove_pending

        remove_pending()
        print(f"negstiff {args.command}: terminated (nothing written)", file=sys.stderr)
        return 143
    except BrokenPipeError:
        return 141


def run() -> None:
    """The installed command: ``main``, then an exit that skips the interpreter's teardown. Everything
    the command writes is written (atomically) and its worker processes joined inside ``main``; the
    teardown would only free the loaded libraries' state, which took 0.2 s of a 2.7 s ``identify nsi``
    (numba's compiled kernels; measured). An exception escaping ``main`` takes the usual way out.
    """
    rc = main()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except BrokenPipeError:
        rc = 141
    os._exit(int(rc or 0))
