"""The child process of one simulation: ``python -m realitygap._child``.

Reads a job as JSON on standard input, runs it with the engines of the
extension and writes the trajectory as JSON on standard output, as
``realitygap __run-one`` does for the command. Ctrl-C is left to the parent
(which kills the child and keeps the finished runs), so SIGINT is ignored
here.
"""

import signal
import sys

signal.signal(signal.SIGINT, signal.SIG_IGN)

from realitygap import _native  # noqa: E402

if __name__ == "__main__":
    sys.exit(_native.run_one())
