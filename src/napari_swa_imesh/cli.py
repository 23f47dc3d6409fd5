"""The ``swa-imesh`` command line: one sub-command per step of the pipeline.

Every sub-command returns 0 on success; bad input is reported as one sentence on
stderr with exit status 2 (never a traceback). SIGTERM (``kill``, ``timeout``, batch
schedulers) and Ctrl-C stop a run the same way, through the atomic writer's cleanup: one
sentence, exit status 143 or 130, no partial output.
"""

from __future__ import annotations

import argparse
import importlib
import re
import signal
import sys
import threading
import warnings

__all__ = ["main", "build_parser"]

#: the module registering each group of sub-commands, in the order help lists them, and
#: the commands it registers: a command imports only its own group (importing the
#: segmentation package and scipy.ndimage cost ``swa-imesh mesh`` a second or more)
COMMAND_MODULES = {
    ".segmentation._cli": ("res", "segment", "samples-from-truth", "evaluate"),
    ".mesh._cli": ("mesh", "bounds"),
    ".simulate._cli": ("simulate",),
    ".pipeline._cli": ("batch",),
    "._demo": ("demo",),
    "._glossary": ("glossary",),
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``swa-imesh`` parser: every sub-command, or only `command`'s group when it
    names one (the same parser for that command, without importing the others)."""
    parser = argparse.ArgumentParser(
        prog="swa-imesh",
        description="Image -> SWA segmentation -> IMESH finite-element mesh.",
        epilog="Terms (SWA, IMESH, RES, eps_l, eps_m, k_eff, ...): swa-imesh glossary.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    groups = [m for m, names in COMMAND_MODULES.items() if command in names]
    for name in groups or COMMAND_MODULES:
        module = importlib.import_module(name, __package__)
        (getattr(module, "add_commands", None) or module.add_command)(sub)
    return parser


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread so every ``finally`` (cleanup) runs."""


def _on_sigterm(signum, frame):
    # a second SIGTERM must not cut the cleanup of the first short
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise _Terminated


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv[0] if argv else None)
    args = parser.parse_args(argv)
    prefix = f"swa-imesh {args.command}"
    if threading.current_thread() is not threading.main_thread():
        return _run(args, prefix)
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        return _run(args, prefix)
    except _Terminated:
        print(f"{prefix}: stopped by SIGTERM; unfinished outputs were removed (files are "
              "written whole or not at all), run it again to finish.", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print(f"{prefix}: stopped (interrupted); unfinished outputs were removed, run it "
              "again to finish.", file=sys.stderr)
        return 128 + signal.SIGINT
    finally:
        signal.signal(signal.SIGTERM, previous)


def _run(args, prefix: str) -> int:
    def show(message, category, filename, lineno, file=None, line=None):
        print(f"{prefix}: warning: {message}", file=sys.stderr)

    with warnings.catch_warnings():
        warnings.simplefilter("always", UserWarning)
        warnings.showwarning = show
        try:
            return int(args.func(args) or 0)
        except MemoryError as exc:
            # numpy says "Unable to allocate 8.00 GiB for an array with shape ..."
            size = re.search(r"allocate ([0-9.]+ [KMGTP]?i?B)", str(exc))
            what = f" (an allocation of {size.group(1)} failed)" if size else ""
            print(f"{prefix}: error: ran out of memory{what}; crop the image, coarsen "
                  "(downsample) it, or work on a sub-volume, or run on a machine with more "
                  "memory.", file=sys.stderr)
            return 2
        except (ValueError, TypeError, OSError, KeyError) as exc:
            msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
            print(f"{prefix}: error: {msg}", file=sys.stderr)
            return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
