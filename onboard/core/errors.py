"""Exceptions shared by the command-line tools."""


class UsageError(Exception):
    """Bad usage or unreadable input: the CLI prints one line and exits with status 2."""


class OutputFailed(Exception):
    """An output could not be written once the work had begun (a full disk, a directory
    removed meanwhile; every path was checked before, :mod:`onboard.core.outputs`): the
    CLI prints one line naming it and exits with status 1."""
