"""The one exception type that the CLI turns into a one-line message and exit code 2."""


class SasmiError(ValueError):
    """Bad user input: a preset field, a file, a flag. The message names the culprit."""
