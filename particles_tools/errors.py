"""What the command-line tools raise for the user: one line per problem, never a traceback.

Exit codes: 0 ok, 2 bad input, 3 simulation failure, 4 output failure (folder cannot be created or
written, disk full), 128 + signal number when stopped by SIGINT (130) or SIGTERM (143), 141 when
stdout's reader went away. Kept in
their own module so that ``cli`` (which dispatches), ``commands`` and ``viewer`` (which raise)
import it and not each other.
"""
from __future__ import annotations

EXIT_OK, EXIT_BAD_INPUT, EXIT_SIM_FAILED, EXIT_OUTPUT_FAILED = 0, 2, 3, 4
EXIT_BROKEN_PIPE = 128 + 13  # stdout closed by its reader (SIGPIPE's code, as `yes | head` gives)


class UserError(Exception):
    """A message for the user, never shown with a traceback: one line per problem."""

    exit_code = EXIT_BAD_INPUT


class SimulationError(UserError):
    exit_code = EXIT_SIM_FAILED


class OutputFailure(UserError):
    exit_code = EXIT_OUTPUT_FAILED


class Stopped(UserError):
    """Stopped by a signal after writing the frames already simulated: exit 128 + signum."""

    def __init__(self, message, signum):
        super().__init__(message)
        self.exit_code = 128 + int(signum)
