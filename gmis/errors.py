"""One exception type for bad user input: the CLI prints its message on one line."""


class GmisInputError(Exception):
    """Bad user input (recipe, data file, option). The message names the file/key and the
    problem; the CLI prints it as one line and exits with status 2."""

    def __init__(self, message: str, source: str | None = None):
        self.source = source
        super().__init__(f"{source}: {message}" if source else message)
