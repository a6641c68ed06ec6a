"""Exceptions shared by the command-line tools."""


class UsageError(Exception):
    """Bad usage or unreadable input: the CLI prints one line and exits with status 2."""
