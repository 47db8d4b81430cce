"""The ``tolsim`` command line: a thin layer over the Python API.

Each subcommand lives in its own module exposing ``add_parser(subparsers)`` and
``run(args) -> int``. Bad input raises :class:`UsageError` (or goes through the parser), which
prints one line ``tolsim <command>: error: <message>`` on stderr and exits with code 2.

Imports of the study stack sit inside the functions that need them, deliberately (each marked
``# noqa: PLC0415``): a subcommand loads only what it uses, so ``tolsim ball`` or ``--help``
start in a fraction of a second.
"""

import argparse
import contextlib
import importlib
import os
import sys
import warnings

#: subcommand -> module (imported lazily so ``tolsim ball`` never imports xarray/matplotlib)
SUBCOMMANDS = {
    "ball": "tolsim.cli.ball",
    "run": "tolsim.cli.run",
    "paper": "tolsim.cli.paper",
    "report": "tolsim.cli.report",
    "carriage": "tolsim.cli.carriage",
    "compare": "tolsim.cli.compare",
    "allocate": "tolsim.cli.allocate",
    "warmup": "tolsim.cli.warmup",
}

SUMMARIES = {
    "ball": "velocity deviation of one ball from its contact angles and forces",
    "run": "Monte Carlo tolerance study from a TOML config to a netCDF result",
    "paper": "reproduce the source paper's figures and Table 2",
    "report": "HTML report of a study result file or a sweep",
    "carriage": "load distribution of one carriage on its ball tracks, with preload",
    "compare": "studies side by side: statistics, differences with intervals, config changes",
    "allocate": "least-cost tolerances that meet a probabilistic target (P, quantile)",
    "warmup": "compile the kernels of the studies ahead of a first run",
}


class UsageError(Exception):
    """Bad user input: reported as one line and exit code 2."""


def integer_at_least(minimum, what, maximum=None):
    """An argparse ``type`` accepting whole numbers >= ``minimum`` (and <= ``maximum``).

    A bad value becomes ``argument --flag: expected <what>, got '...'`` (argparse names the
    flag), reported as one line with exit code 2.
    """

    def parse(text):
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum or (maximum is not None and value > maximum):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return value

    return parse


def path_argument(text):
    """An argparse ``type`` for a file or folder path: any text but an empty one.

    An empty path (``-o "$OUT"`` with OUT unset) was taken as no path at all by some
    commands, which then wrote to their default place, and by others only after their work
    (``cannot write to :``); it is now ``argument -o/--out: expected a path, got ''``, one
    line with exit code 2, before any work.
    """
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a path, got {text!r}")
    return text


class Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line and exit code 2 (no usage dump)."""

    def error(self, message):
        raise UsageError(message)


class _HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Descriptions as written; an option's default appended only when it says something.

    ``ArgumentDefaultsHelpFormatter`` appends ``(default: X)`` to every option, which gave
    ``(default: None)`` on options whose default is "not given" (the help text says what
    happens then), ``(default: False)`` on on/off flags, and a second default where the help
    text already states one. Here the default is appended only to an option that takes a
    value, has a real default, and whose help does not mention a default already.
    """

    def _get_help_string(self, action):
        text = action.help or ""
        default = action.default
        if (default is None or default is argparse.SUPPRESS or action.nargs == 0
                or isinstance(default, bool) or "default" in text.lower()):
            return text
        if not action.option_strings and action.nargs not in (argparse.OPTIONAL,
                                                               argparse.ZERO_OR_MORE):
            return text
        return f"{text} (default: %(default)s)"


@contextlib.contextmanager
def warnings_as_lines(command):
    """Print each of tolsim's own warnings issued inside as one line on stderr, once.

    A warning whose category tolsim defines (an unusual config value,
    :class:`tolsim.io.config.reader.ConfigWarning`; a result file without checksums,
    :class:`tolsim.io.checksums.UnverifiedResultWarning`) becomes ``<command>: warning:
    <message>``, each text once (a sweep reads its config once per point); other warnings go
    to the previous handler.
    """
    shown, previous = set(), warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if category.__module__.startswith("tolsim."):
            text = " ".join(str(message).split())
            if text not in shown:
                shown.add(text)
                print(f"{command}: warning: {text}", file=sys.stderr)
            return
        previous(message, category, filename, lineno, file, line)

    with warnings.catch_warnings():  # (which also resets the once-per-place registries)
        # shown, whatever the filters say (they are part of the answer)
        warnings.filterwarnings("default", category=UserWarning, module=r"tolsim\.")
        warnings.showwarning = show
        yield


def build_parser(argv=()):
    """The top-level parser; only the subcommand named in ``argv`` is imported."""
    from tolsim import __version__  # noqa: PLC0415

    parser = Parser(
        prog="tolsim",
        description=(
            "tolsim: will the balls of a four-point-contact linear guide run into each other, "
            "how likely, and how soon?"
        ),
        epilog="Run 'tolsim COMMAND --help' for the options and examples of a command.",
        formatter_class=_HelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"tolsim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    requested = next((a for a in argv if not a.startswith("-")), None)
    for name, module in SUBCOMMANDS.items():
        # Only import the module of the command that runs (keeps start-up light); the others
        # still appear in the listing.
        if name == requested:
            importlib.import_module(module).add_parser(sub, formatter_class=_HelpFormatter)
        else:
            sub.add_parser(name, help=SUMMARIES[name], add_help=False)
    return parser


def main(argv=None):
    """Entry point of the ``tolsim`` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    requested = next((a for a in argv if not a.startswith("-")), None)
    command = f"tolsim {requested}" if requested in SUBCOMMANDS else "tolsim"
    try:
        parser = build_parser(argv)
        args = parser.parse_args(argv)
        command = f"tolsim {args.command}" if args.command else "tolsim"
        if args.command is None:
            parser.print_help()
            return 2
        module = importlib.import_module(SUBCOMMANDS[args.command])
        with warnings_as_lines(command):
            return module.run(args)
    except UsageError as exc:
        msg = " ".join(str(exc).split())  # always one line
        print(f"{command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `tolsim run ... | head`: the reader left; the file is written
        # (the summary is printed after it). Silence the flush at exit, as SIGPIPE would.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


if __name__ == "__main__":
    sys.exit(main())
