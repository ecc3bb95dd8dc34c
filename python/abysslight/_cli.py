"""The ``abysslight`` command installed by the Python package: the command line compiled into the extension."""

import signal
import sys


def main() -> None:
    from ._abysslight import run_cli

    # Ctrl-C as for the native binary: the command installs its own handler where it finishes cleanly (a batch
    # run prints how to --resume, --watch ends its watch); elsewhere it ends the process.
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    sys.exit(run_cli(["abysslight", *sys.argv[1:]]))


if __name__ == "__main__":
    main()
