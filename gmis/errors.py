"""One exception type for bad user input: the CLI prints its message on one line."""

from gnss.errors import GnssInputError


class GmisInputError(GnssInputError):
    """Bad user input (recipe, data file, option). The message names the file/key and the
    problem; the CLI prints it as one line and exits with status 2. It is a
    gnss.errors.GnssInputError (same fields and message), the error the gnss package raises
    for its own inputs, so the CLI catches both as the base class."""
