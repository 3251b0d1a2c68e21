"""The gnss package's one exception type for bad user input (a RINEX/SP3 file, an option).

The message names the file (and the key or line where there is one) and the problem, so
a command-line front end can print it as one line: ``<source>: <message>``.
gmis.errors.GmisInputError subclasses it, so one ``except GnssInputError`` catches both.
"""


class GnssInputError(Exception):
    """Bad user input. ``source``: the file or option at fault (or None); str(error) is
    ``"<source>: <message>"`` (just the message without a source)."""

    def __init__(self, message: str, source: str | None = None):
        self.source = source
        super().__init__(f"{source}: {message}" if source else message)
