"""``mlagents-like-learn``: the drop-in for ``mlagents-learn``.

User errors (trainer.errors.UserError) become one line on stderr and exit code 2; a traceback
only with --debug. SIGINT, SIGTERM, SIGQUIT and SIGUSR1 (what Slurm sends before a time limit)
all stop training the same way Ctrl-C does: a final checkpoint and ONNX are written first
(``trainer.stop``: the stop happens at a safe point, not where the signal lands).
"""
from __future__ import annotations

import logging
import os
import platform
import signal
import sys

LOGO = r"""
            ┌─┐┌┐┌┌─┐┌─┐┌┐┌┌┬┐┌─┐   ┬  ┬┬┌─┌─┐
 mlagents   ├─┤│││ ┬├┤ │││ │ └─┐───│  │├┴┐├┤
            ┴ ┴┘└┘└─┘└─┘┘└┘ ┴ └─┘   ┴─┘┴┴ ┴└─┘
"""

logger = logging.getLogger("mlagents_like")


_USER_BLAS_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def limit_blas_threads(blas_threads: int | None, environ=os.environ) -> None:
    """One BLAS thread for numpy unless MLAGENTS_LIKE_BLAS_THREADS (``blas_threads``) or the
    user's own OPENBLAS_NUM_THREADS / OMP_NUM_THREADS / MKL_NUM_THREADS says otherwise. Must run
    before numpy is imported. The trainer's matrices are small (a batch of 64 through 128 units):
    OpenBLAS's extra thread does not speed them up, but it busy-waits after every call: in a
    60k-step ball3d run the trainer used 36-38 CPU-seconds with two threads, 24 with one, and
    the difference is taken from the simulators, which share the cores."""
    if blas_threads is None and any(var in environ for var in _USER_BLAS_VARS):
        return
    threads = str(blas_threads or 1)
    environ["OPENBLAS_NUM_THREADS"] = threads
    environ["MKL_NUM_THREADS"] = threads


def read_environment(environ=os.environ):
    """The run's MLAGENTS_LIKE_* choices (trainer.config.env_vars), with numpy's BLAS threads
    limited accordingly: the first thing ``main`` does, before numpy is imported. ConfigError
    for a bad value."""
    from trainer.config.env_vars import EnvVars

    env_vars = EnvVars.from_environ(environ)
    limit_blas_threads(env_vars.blas_threads, environ)
    return env_vars


def setup_logging(debug: bool) -> None:
    fmt = "%(asctime)s %(levelname)s [%(filename)s:%(lineno)d] %(message)s" if debug else "[%(levelname)s] %(message)s"
    handler = logging.StreamHandler(sys.stdout)
    handler.setFormatter(logging.Formatter(fmt))
    root = logging.getLogger("mlagents_like")
    root.handlers[:] = [handler]
    root.setLevel(logging.DEBUG if debug else logging.INFO)
    root.propagate = False


def version_lines() -> list[str]:
    # installed versions from package metadata: importing torch here would delay launching the
    # simulators by the whole torch import
    from importlib.metadata import PackageNotFoundError, version

    from protos.versions import COMMUNICATION_VERSION
    from trainer import __version__

    def installed(name: str) -> str:
        try:
            return version(name)
        except PackageNotFoundError:
            return "not installed"

    return [
        "Version information:",
        f"  mlagents-like: {__version__},",
        f"  Communicator API: {COMMUNICATION_VERSION},",
        f"  PyTorch: {installed('torch')},",
        f"  NumPy: {installed('numpy')},",
        f"  Python: {platform.python_version()}",
    ]


def log_versions() -> None:
    for line in version_lines():
        logger.info(line)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    setup_logging(debug)
    from protos.errors import ProtocolError
    from trainer.errors import UserError

    try:
        env_vars = read_environment()  # before the flags: it must limit BLAS before numpy loads
        from trainer.config.cli_args import parse_run_options

        options = parse_run_options(argv)
        from trainer.config.support import check_demo_paths, check_supported

        check_supported(options)  # before the results folder or a simulator exists
        check_demo_paths(options)
        if options.check:  # docs/mirror.md: no simulator, no results folder
            from trainer.config.spec_check import run_check

            return run_check(options)
        print(LOGO)
        from trainer.stop import STOP

        STOP.install()
        if hasattr(signal, "SIGXFSZ"):  # past `ulimit -f` a write fails with EFBIG (one message), no core dump
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        if options.capture_spec is not None:
            from trainer.capture import capture_spec

            log_versions()
            return capture_spec(options, env_vars)
        # the simulators launch before the loop's modules are imported (torch among them, in the
        # background): they boot meanwhile (docs/performance.md, "Start-up and exit")
        from trainer.run_setup import launch_simulators

        launched = launch_simulators(options, env_vars)
        try:
            log_versions()  # after the launch: reading the packages' metadata takes 40-50 ms
            from trainer.run import run_training
        except BaseException:
            launched.pool.close()
            raise
        return run_training(options, env_vars, launched)
    except (UserError, ProtocolError) as err:
        if debug:
            logger.exception("error")
        print(f"mlagents-like-learn: error: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt:
        return 130


def entry() -> None:
    """The console script: ``main``, then a fast exit. Everything the run writes is closed and
    flushed by then (checkpoints, ONNX, TensorBoard, timers, the simulators are stopped); what
    is left is the interpreter's teardown of torch and numpy's module graph, measured at
    0.5-0.6 s, which ``os._exit`` skips after flushing the standard streams and logging."""
    from trainer.fast_exit import exit_now

    exit_now(main())


if __name__ == "__main__":
    entry()
